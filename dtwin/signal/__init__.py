"""Signal processing of measured or simulated records: spectra, PSD, order tracking, time-
synchronous averaging, envelope, cepstrum, condition indicators and vibration units.
Independent of the spec and the simulation."""
