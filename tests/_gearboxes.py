"""Gearboxes other than the paper's, for tests of what must hold on any machine."""

from __future__ import annotations

#: A four-planet gearbox (20/40/100, module 3, 20 Hz input, 120 N·m): its drive's start-up
#: transient outlasts the default settling time of a tiled simulation, 0.1 s (hunting period
#: 0.3 s), so a tiled response must be checked and settled longer.
SLOW_SETTLING = {
    "gears": {"z_sun": 20, "z_planet": 40, "z_ring": 100, "n_planets": 4, "module": 0.003,
              "pressure_angle": 0.3490658503988659, "face_width": 0.025},
    "operating": {"f_sun": 20.0, "load_torque": 120.0},
    "sensor": {"sample_rate": 8000.0},
}

#: A four-planet, sequentially phased gearbox (22/38/98, module 2, 25 Hz input, 60 N·m;
#: Zs/N = 5.5, Zr/N = 24.5): records of it made by the translational twin carry a sun fault's
#: comb lifted by translational modes the torsional twin lacks.
SEQUENTIAL = {
    "gears": {"z_sun": 22, "z_planet": 38, "z_ring": 98, "n_planets": 4, "module": 0.002,
              "pressure_angle": 0.3490658503988659, "face_width": 0.02},
    "operating": {"f_sun": 25.0, "load_torque": 60.0},
    "sensor": {"sample_rate": 5000.0},
}

#: A four-planet gearbox (24/36/96, module 2.5, 25 Hz input, 60 N·m, 10 kHz, accelerometer on
#: top), the translational twin: a calibration on a healthy record of it splits the mesh
#: harmonics' excitation from the response otherwise than the records do
#: (tests/data/four_planet_calibrated.toml), and a planet fault on one flank of the tooth
#: reads many times small when fitted on the other.
FOUR_PLANET = {
    "name": "four-planet",
    "gears": {"z_sun": 24, "z_planet": 36, "z_ring": 96, "n_planets": 4, "module": 0.0025,
              "pressure_angle": 0.3490658503988659, "face_width": 0.025},
    "material": {"youngs_modulus": 2.06e11, "poisson": 0.3, "density": 7850.0},
    "operating": {"f_sun": 25.0, "load_torque": 60.0},
    "sensor": {"angle": 1.5707963267948966, "direction": "vertical",
               "quantity": "acceleration", "sample_rate": 10000.0},
    "model": {"kind": "translational"},
}
