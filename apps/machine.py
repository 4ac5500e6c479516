"""Machine description printed with every benchmark: CPU, cores, tool versions (what the numbers depend on)."""
from __future__ import annotations

import os
import platform
import subprocess

import numba
import numpy as np

from ..backends.c.loader import cflags, compiler
from ..runtime.base.errors import TensormassError


def machine_info() -> dict:
    """CPU model, core counts and tool versions (what the numbers depend on)."""
    info = {"cpu": platform.processor() or platform.machine(), "machine": platform.machine(),
            "system": f"{platform.system()} {platform.release()}",
            "logical_cores": os.cpu_count(), "python": platform.python_version(),
            "numpy": np.__version__, "numba": numba.__version__}
    try:
        info["usable_cores"] = len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        info["usable_cores"] = os.cpu_count()
    try:
        with open("/proc/cpuinfo", encoding="utf-8", errors="replace") as handle:
            text = handle.read()
        for line in text.splitlines():
            if line.startswith("model name"):
                info["cpu"] = line.split(":", 1)[1].strip()
                break
        physical = {(b.get("physical id"), b.get("core id"))
                    for b in ({k.strip(): v.strip() for k, _, v in (ln.partition(":") for ln in block.splitlines())}
                              for block in text.split("\n\n")) if "core id" in b}
        if physical:
            info["physical_cores"] = len(physical)
    except OSError:
        pass
    try:
        command = compiler()
        done = subprocess.run(command + ["--version"], capture_output=True, text=True, timeout=60)
        info["cc"] = (done.stdout or done.stderr).splitlines()[0].strip()
        info["cflags"] = " ".join(cflags())
    except (TensormassError, OSError, subprocess.SubprocessError, IndexError):
        info["cc"] = None
    return info


def format_machine(info: dict) -> str:
    cores = f"{info.get('physical_cores', '?')} physical / {info.get('logical_cores')} logical, {info.get('usable_cores')} usable"
    return (f"CPU: {info['cpu']} ({cores})\n"
            f"python {info['python']}, numpy {info['numpy']}, numba {info['numba']}, "
            f"cc: {info.get('cc') or 'none'} {info.get('cflags', '')}".rstrip())
