"""The model: the gear set (geometry, kinematics, mesh stiffness, faults, lumped and modal
models), the parts a twin is assembled from (`parts/`), the drive and load that turn it
(`motor/`), the registry of part types and the twin itself. Imports nothing above it: no
simulation, spec, signal or report."""
