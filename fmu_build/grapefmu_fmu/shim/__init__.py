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


def forwarders(version: int, template: str) -> str:
    """C forwarders for every function of fmi<version>FunctionTypes.h that the template does not define."""
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
        if ret == "void":
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

