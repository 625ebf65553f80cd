"""Compile the FMU's binary: shim.c plus a forwarder for every other function of the FMI headers.

The forwarders are generated from the function-type declarations of the FMI 2.0 / 3.0 headers that
fmpy ships (`fmpy/c-code`), so no FMI signature is written by hand twice: each unwraps the instance,
calls pythonfmu's function of the same name and settles the status the Python side asked for."""
from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
import sysconfig
from pathlib import Path

from grapefmu import GrapefmuError

HERE = Path(__file__).parent
TEMPLATE = HERE / "shim.c"
INNER_LIBRARY = "libpythonfmu-export.so"  # pythonfmu's binary, renamed next to ours
PYTHON_FILE = "python.txt"                # resources: where this machine's libpython and interpreter are

_TYPEDEF = re.compile(r"typedef\s+([\w\s\*]+?)\s*(fmi[23]\w+)TYPE\s*\(([^;]*?)\)\s*;", re.S)


def headers() -> Path:
    import fmpy
    return Path(fmpy.__file__).parent / "c-code"


def _params(text: str) -> list[tuple[str, str]]:
    """[(declaration with a name a<k>, name a<k>)] for a parameter list ('void' is none)."""
    text = re.sub(r"/\*.*?\*/", "", text, flags=re.S).strip()
    if text in ("", "void"):
        return []
    out = []
    for k, p in enumerate(text.split(",")):
        p = " ".join(p.split())
        name = f"a{k}"
        base, bracket = (p.split("[", 1) + [""])[:2]
        bracket = "[" + bracket if bracket else ""
        words = base.replace("*", "* ").split()
        typed = [w for w in words if w != "const"]
        if len(typed) >= 2 and not typed[-1].endswith("*"):  # the last word is the parameter's own name
            words = words[:-1]
        out.append((" ".join(words).replace("* ", "*") + f" {name}{bracket}", name))
    return out


#: the FMI 3 functions forwarded to pythonfmu3 (besides shim.c's own): every other one is refused in the binary, as
#: this FMU has no variables of the other types, no event, configuration or continuous-time mode, no clocks and no
#: derivatives, and pythonfmu3 answers most of them with a C++ exception that aborts the host
FMI3_FORWARDED = {"fmi3SetDebugLogging", "fmi3ExitInitializationMode", "fmi3Terminate", "fmi3Reset",
                  *(f"fmi3{a}{t}" for a in ("Get", "Set") for t in ("Float64", "Int32", "Int64", "UInt64", "Boolean",
                                                                      "String")),
                  "fmi3GetFMUState", "fmi3SetFMUState", "fmi3FreeFMUState", "fmi3SerializedFMUStateSize",
                  "fmi3SerializeFMUState", "fmi3DeserializeFMUState"}
#: an accessor of a type this FMU has no variable of: fine with no value references, else an unknown one
_NO_VARIABLES = re.compile(r"fmi3(?:Get|Set)(Float32|U?Int8|U?Int16|UInt32|Binary|Clock)")


def _refusing(name: str, ps: list[tuple[str, str]]) -> str:
    """The body of a function the binary refuses (FMI3_FORWARDED), logging why."""
    head = f"    Instance* I = (Instance*){ps[0][1]};\n"
    kind = _NO_VARIABLES.fullmatch(name)
    if kind:
        return (head + f"    if ({ps[2][1]} == 0) return fmi3OK;\n"
                f'    say(I, STATUS_ERROR, "{name}: value reference %u: this FMU has no variable of type '
                f'{kind[1]}", (unsigned){ps[1][1]}[0]);\n    return fmi3Error;\n')
    return (head + f'    say(I, STATUS_ERROR, "{name}: not supported by this FMU (co-simulation in step mode only: no '
            f'event, configuration or continuous-time mode, clocks or derivatives)");\n    return fmi3Error;\n')


def forwarders(version: int, template: str) -> str:
    """C forwarders for every function of fmi<version>FunctionTypes.h that the template does not define (for FMI 3,
    refusals for those it does not forward)."""
    text = (headers() / f"fmi{version}FunctionTypes.h").read_text()
    defined = set(re.findall(r"^\w[\w\s\*]*?\b(fmi[23]\w+)\s*\(", template, re.M))
    out = []
    for ret, name, params in _TYPEDEF.findall(text):
        ret = " ".join(ret.split())
        if name in defined:
            continue
        ps = _params(params)
        if not ps or not ps[0][0].startswith(f"fmi{version}Instance" if version == 3 else "fmi2Component"):
            raise GrapefmuError(f"FMI header: {name} does not take the instance first; write it in shim.c")
        decl = ", ".join(d for d, _ in ps)
        args = ", ".join(["I->inner"] + [n for _, n in ps[1:]])
        inner = f"INNER({name})"
        if version == 3 and name not in FMI3_FORWARDED:
            body = _refusing(name, ps)
        elif ret == "void":
            body = f"    Instance* I = (Instance*){ps[0][1]};\n    if (I && {inner}) {inner}({args});\n"
        else:
            body = (f"    Instance* I = (Instance*){ps[0][1]};\n"
                    f"    {name}TYPE* f = {inner};\n"
                    f"    if (!I || !f) return ({ret})STATUS_ERROR;\n"
                    f"    ENTER(I);\n"
                    f"    return ({ret})settle(f({args}));\n")
        out.append(f"{ret} {name}({decl})\n{{\n{body}}}\n")
    return "\n".join(out)


def source(version: int) -> str:
    template = TEMPLATE.read_text()
    return template + "\n" + forwarders(version, template)


def compile_binary(version: int, dest: Path) -> None:
    """Compile the FMU's binary for this machine into `dest` (needs a C compiler: cc, or $CC)."""
    cc = os.environ.get("CC") or shutil.which("cc") or shutil.which("gcc")
    if not cc:
        raise GrapefmuError("build-fmu needs a C compiler (cc or $CC) to build the FMU's binary")
    src = dest.with_suffix(".c")
    src.write_text(source(version))
    cmd = [cc, "-shared", "-fPIC", "-O2", "-fvisibility=default", f"-DFMI_VERSION={version}",
           f'-DFMI_HEADER="fmi{version}Functions.h"', f"-I{headers()}", "-o", str(dest), str(src), "-ldl", "-lpthread"]
    done = subprocess.run(cmd, capture_output=True, text=True)
    src.unlink()
    if done.returncode != 0:
        raise GrapefmuError(f"compiling the FMU's binary failed:\n{done.stderr.strip()}")


def python_file() -> str:
    """The libpython and interpreter of the build machine, for hosts that are not Python programs."""
    libdir, soname = sysconfig.get_config_var("LIBDIR"), sysconfig.get_config_var("INSTSONAME")
    return f"libpython={Path(libdir) / soname}\npython={sys.executable}\n"

