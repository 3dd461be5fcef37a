"""dtwin.identify.uncertainty: the search for a lower loss (``Uncertainty.better``) when more than
one profiled or scanned parameter passes a point below the optimum's loss (issue 53: the loss
was compared with the parameter vector, which raised after a 17-minute identify)."""

import numpy as np
from scipy.optimize import minimize_scalar

from dtwin.identify.uncertainty import CHI2_95, analyse

_NOISE = 0.01 * np.random.default_rng(7).normal(size=60)


def test_scan_of_two_parameters_keeps_the_lowest_loss():
    """Two scanned stiffnesses, each with a second well lower than the given optimum: `better`
    is the point of lowest loss among them. Closed form per parameter, v_i = θ_i: residuals
    (v² − u², d_i (v − u)), wells at ±u; the optimum given is (−u, −u), the well at +u of
    parameter i lies lower by (2 u d_i)², so the deeper tilt wins."""
    from dtwin.identify.params import ParameterSet

    u = 0.375 * np.log(10.0)
    names = ("k_sun_planet", "k_ring_planet")
    pset = ParameterSet.build(list(names), initial={n: 1e8 for n in names})
    for depths, deeper in (((0.05, 0.08), 1), ((0.08, 0.05), 0)):
        def res(th, depths=depths):
            return np.concatenate([np.ravel([[v * v - u * u, d * (v - u)]
                                             for v, d in zip(th, depths, strict=True)]), _NOISE])

        th = np.array([-u, -u])
        h = 1e-6
        J = np.stack([(res(th + h * e) - res(th - h * e)) / (2 * h) for e in np.eye(2)], axis=1)
        unc = analyse(pset, th, res(th), J, np.arange(64), scan=names,
                      profile_fn=lambda ths, res=res: np.stack([res(t) for t in ths]))
        assert unc.scanned == names and unc.better is not None
        name, th_best, rss_best = unc.better
        assert name == names[deeper]
        assert abs(th_best[deeper] - u) < 0.05 and abs(th_best[1 - deeper] + u) < 0.01
        rss0 = float(np.sum(res(th) ** 2))
        assert (rss0 - rss_best) / unc.s2 > CHI2_95
        assert rss_best == float(np.sum(res(th_best) ** 2))


def test_profiles_of_two_severities_keep_the_lowest_loss():
    """Two severities near 0 (profiled), each with a second well near 0.6 lower than the
    optimum (closed form of tests/test_identify_identifiability.py per severity: residuals
    (x − 0.3, 20((x − 0.3)² − 0.297²), t_i |1 − x|)): `better` is the one whose tilt makes its
    second well the lower."""
    from dtwin.identify.params import ParameterSet

    names = ("sun_fault", "ring_fault")
    pset = ParameterSet.build(list(names), initial={n: 0.3 for n in names})

    def one(x, t):
        w = x - 0.3
        return [w, 20.0 * (w * w - 0.297**2), t * abs(1.0 - x)]

    for tilts, deeper in (((0.3, 0.45), 1), ((0.45, 0.3), 0)):
        def res_x(xs, tilts=tilts):
            return np.concatenate([np.ravel([one(x, t) for x, t in zip(xs, tilts, strict=True)]),
                                   _NOISE])

        def profile_fn(thetas, res_x=res_x):
            return np.stack([res_x(np.asarray(pset.values(t))) for t in np.asarray(thetas)])

        xs = [minimize_scalar(lambda x, t=t: np.sum(np.square(one(x, t))), bounds=(1e-4, 0.2),
                              method="bounded", options={"xatol": 1e-10}).x for t in tilts]
        th = np.asarray(pset.theta(xs))
        h = 1e-6
        J = np.stack([(profile_fn([th + h * e]) - profile_fn([th - h * e]))[0] / (2 * h)
                      for e in np.eye(2)], axis=1)
        unc = analyse(pset, th, res_x(xs), J, np.arange(66), profile_fn=profile_fn)
        assert unc.profiled == names and unc.better is not None
        name, th_best, rss_best = unc.better
        assert name == names[deeper]
        assert 0.5 < float(pset.values(th_best)[deeper]) < 0.7
        assert (float(np.sum(res_x(xs) ** 2)) - rss_best) / unc.s2 > CHI2_95
