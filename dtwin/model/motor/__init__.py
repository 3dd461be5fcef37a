"""What turns the gearbox and what brakes it: the drive/load interface, the PMSM, the induction
motor, the ideal speed source, the flexible input shaft, torque ripple, speed fluctuation and
the load torques on the carrier."""
