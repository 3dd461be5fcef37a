"""Solving the twin in time: the diffrax solve and the DAQ (`simulate`), the integrator, the
periodic steady state, the sensor's frequency response, the accepted input speeds and the
memory a run will need."""
