"""The grapefmu simulator as an FMI co-simulation unit (FMI 2.0 via pythonfmu, FMI 3.0 via pythonfmu3).

`core.FmuCore` holds everything that does not depend on the FMI version; `fmi2` and `fmi3` only
register its variables with pythonfmu and translate statuses; `build` packages an FMU for a scene.
"""
