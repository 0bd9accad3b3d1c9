"""Hostile and careless inputs, round 3 (issue 29): each test makes the attack for real (real FMUs built from
our C sources and rewritten, real files, real signals, real processes) and checks the refusal or the rows kept."""

from __future__ import annotations

import json
import os
import resource
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

from cosim.fmus.build import ensure_built
from cosim.fmus.conformance import ensure_built as ensure_conformance_built

REPO = Path(__file__).resolve().parent.parent


def _cosim(*args: str, timeout: float = 180, env: dict | None = None, memory_mb: int | None = None,
           **popen) -> subprocess.CompletedProcess:
    """``cosim`` in a fresh process (optionally with its address space capped at ``memory_mb``)."""

    def cap():
        if memory_mb:
            resource.setrlimit(resource.RLIMIT_AS, (memory_mb << 20, memory_mb << 20))

    return subprocess.run([sys.executable, "-m", "cosim.cli.main", *args], capture_output=True, text=True,
                          env=dict(os.environ, PYTHONPATH=str(REPO / "src"), **(env or {})), timeout=timeout,
                          preexec_fn=cap, **popen)


# 1. FMI 3.0 array sizes are bounded ------------------------------------------------------------------------------

def _gain_array_sized(target: Path, size: str) -> Path:
    """gain_array (FMI 3.0, arrays u and y of 3) with both arrays declared as ``<Dimension start=size>``."""
    source = ensure_built("gain_array", 3)
    with zipfile.ZipFile(source) as zin, zipfile.ZipFile(target, "w", zipfile.ZIP_DEFLATED) as zout:
        for info in zin.infolist():
            data = zin.read(info)
            if info.filename == "modelDescription.xml":
                assert b'<Dimension start="3"/>' in data
                data = data.replace(b'start="0.0 0.0 0.0"', b'start="0.0"')
                data = data.replace(b'<Dimension start="3"/>', f'<Dimension start="{size}"/>'.encode())
            zout.writestr(info, data)
    return target


def _spec_of(folder: Path, units: dict, name: str = "spec.json") -> Path:
    path = folder / name
    path.write_text(json.dumps({"units": units, "experiment": {"stop": 0.1, "step": 0.1}}))
    return path


@pytest.mark.parametrize("command", ["validate", "inspect", "run"])
def test_a_billion_element_array_is_refused_under_a_memory_cap(tmp_path, command):
    """Before: one object per element until the memory was gone (inspect: exit 70 and a traceback under a cap)."""
    fmu = _gain_array_sized(tmp_path / "big.fmu", "1000000000")
    spec = _spec_of(tmp_path, {"g": {"fmu": "big.fmu"}})
    target = str(fmu) if command == "inspect" else str(spec)
    done = _cosim(command, target, memory_mb=1500)
    assert done.returncode == 2, done.stderr
    text = done.stdout + done.stderr
    assert "big.fmu" in text and "variable 'u'" in text and "2,000,000,000 elements" in text, text
    assert "above the limit of 1,000,000" in text and "COSIM_ARRAY_ELEMENTS (default 1000000)" in text, text
    assert "Traceback" not in text and "MemoryError" not in text


def test_a_structural_parameter_set_to_a_billion_in_the_spec_is_refused(tmp_path):
    fmu = ensure_conformance_built("structural", 3)
    spec = _spec_of(tmp_path, {"s": {"fmu": str(fmu), "parameters": {"n": 1_000_000_000}}})
    done = _cosim("validate", str(spec), memory_mb=1500)
    assert done.returncode == 2, done.stderr
    assert "structural parameter 'n'" in done.stdout + done.stderr
    assert "set the structural parameter 'n' smaller" in done.stdout + done.stderr
    done = _cosim("run", str(spec), memory_mb=1500)
    assert done.returncode == 2 and "structural parameter 'n' = 1000000000 set by the spec" in done.stdout + done.stderr, done.stderr


@pytest.mark.parametrize("size", ["-5", "-1"])
def test_a_negative_dimension_is_refused_not_listed(tmp_path, size):
    """Before: inspect listed a negative size as an array of '-5' elements and validate said ok.
    (A size that is no whole number, "2.5", is refused already by fmpy's reader, as a modelDescription.xml
    it cannot read.)"""
    _gain_array_sized(tmp_path / "odd.fmu", size)
    for command, target in (("inspect", "odd.fmu"), ("validate", str(_spec_of(tmp_path, {"g": {"fmu": "odd.fmu"}})))):
        done = _cosim(command, target, cwd=tmp_path)
        text = done.stdout + done.stderr
        assert done.returncode == 2, text
        assert f"array size {size} from <Dimension start=\"{size}\"> is not a whole number >= 0" in text, text
        assert "variable 'u'" in text and "Traceback" not in text


def test_the_array_limit_is_raised_on_purpose_and_counts_every_array(tmp_path):
    """gain_array's arrays hold 3 + 3 elements: a limit of 5 refuses it, 6 runs it (y = 2 u = 0)."""
    spec = _spec_of(tmp_path, {"g": {"fmu": str(ensure_built("gain_array", 3))}})
    refused = _cosim("validate", str(spec), env={"COSIM_ARRAY_ELEMENTS": "5"})
    assert refused.returncode == 2 and "6 elements in all, above the limit of 5" in refused.stdout + refused.stderr
    assert _cosim("run", str(spec), env={"COSIM_ARRAY_ELEMENTS": "6"}).returncode == 0
