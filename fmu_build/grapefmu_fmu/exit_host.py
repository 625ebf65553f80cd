"""A Python host that loads, steps and frees an FMU five times and then ends as any script does (no os._exit):
whether it exits normally is what `benchmarks/fmu_exit_aborts.py` counts and
`tests/test_fmu_hardening.py::test_a_python_host_exits_normally_after_freeing_the_fmu` asserts
(docs/reliability.md, "A Python host ends normally after using the FMU").

`python -m grapefmu_fmu.exit_host FMU {2|3}` prints DONE when its FMI calls are through."""
from __future__ import annotations

import sys


def main(path: str, fmi: str) -> None:
    from fmpy import extract, read_model_description  # a host's packages, not the FMU's (as bench_run)
    from fmpy.fmi2 import FMU2Slave
    from fmpy.fmi3 import FMU3Slave

    md = read_model_description(path)
    unzipped = extract(path)
    for k in range(5):
        f = (FMU2Slave if fmi == "2" else FMU3Slave)(guid=md.guid, unzipDirectory=unzipped, instanceName=f"i{k}",
                                                     modelIdentifier=md.coSimulation.modelIdentifier)
        f.instantiate()
        if fmi == "2":
            f.setupExperiment(startTime=0.0)
            f.enterInitializationMode()
        else:
            f.enterInitializationMode(startTime=0.0)
        f.exitInitializationMode()
        f.doStep(0.0, 1e-3)
        f.terminate()
        f.freeInstance()
    print("DONE", flush=True)


if __name__ == "__main__":
    main(*sys.argv[1:3])
