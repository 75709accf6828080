"""Fresh virtual environments for install tests.

A venv created from inside a venv does not see the outer environment's
packages (``system_site_packages`` means the *base* interpreter's), so the
engines would have to be downloaded again. Instead the new environment gets
a ``.pth`` file that adds the running environment's site directories after
its own (``site.addsitedir``, which also runs their ``.pth`` files): the
engines and other dependencies come from there, while whatever a test
installs into the new environment is found first.
"""

from __future__ import annotations

import os
import site
import subprocess
import sys
import sysconfig
import venv
from pathlib import Path


def outer_site_dirs() -> list[str]:
    dirs = [sysconfig.get_paths()["purelib"], sysconfig.get_paths()["platlib"]]
    try:
        dirs += site.getsitepackages()
    except AttributeError:  # pragma: no cover
        pass
    if site.ENABLE_USER_SITE:
        dirs.append(site.getusersitepackages())
    return list(dict.fromkeys(d for d in dirs if os.path.isdir(d)))


def make_venv(path: Path) -> Path:
    """Create a venv at ``path`` that can import the current environment's packages; return its python."""
    venv.EnvBuilder(with_pip=False).create(path)
    py = path / "bin" / "python"
    purelib = subprocess.run([str(py), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
                             capture_output=True, text=True, check=True).stdout.strip()
    lines = "".join(f"import site; site.addsitedir({d!r})\n" for d in outer_site_dirs())
    (Path(purelib) / "zz_outer_env.pth").write_text(lines)
    return py


def pip_install(py: Path, *args: str, timeout: float = 600) -> subprocess.CompletedProcess:
    env = {**os.environ, "PIP_DISABLE_PIP_VERSION_CHECK": "1"}
    return subprocess.run([sys.executable, "-m", "pip", "--python", str(py), "install", "-q", *args],
                          capture_output=True, text=True, env=env, timeout=timeout)
