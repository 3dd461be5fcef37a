"""The bundled preset specs (TOML), shipped inside the package: ``paper-sim``, ``paper-bench``,
``paper-like`` and ``lin-parker``. Load one with :func:`dtwin.spec.preset`."""
