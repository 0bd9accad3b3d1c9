"""Hostile FMU archives: a library from outside the FMU, zip bombs, symlinks, too many members.

Each FMU here is a real one built from fmus/ and then altered the way a
hostile or broken exporter would, so the only difference is the attack.
"""

from __future__ import annotations

import math
import os
import stat
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

import cosim
from cosim.units.fmu.description import FmuProblems, FmuUnitType, platform_folders
from cosim.util.archive import ArchiveError, ArchiveLimits, check_archive, safe_extract
from tests.helpers.paths import REPO


def _cosim(*args: str, env: dict | None = None) -> subprocess.CompletedProcess:
    full_env = dict(os.environ, PYTHONPATH=str(REPO), **(env or {}))
    return subprocess.run([sys.executable, "-m", "cosim.cli.main", *args], capture_output=True, text=True,
                          env=full_env, timeout=120)


def _rewrite(source: Path, target: Path, identifier: str | None = None,
             extra: list[tuple[zipfile.ZipInfo, bytes]] = ()) -> Path:
    """Copy the FMU ``source`` to ``target``, optionally with another modelIdentifier and extra members."""
    with zipfile.ZipFile(source) as zin, zipfile.ZipFile(target, "w", zipfile.ZIP_DEFLATED) as zout:
        for info in zin.infolist():
            data = zin.read(info)
            if info.filename == "modelDescription.xml" and identifier is not None:
                data = data.replace(b'modelIdentifier="linear_ode"', f'modelIdentifier="{identifier}"'.encode())
                assert identifier.encode() in data
            zout.writestr(info, data)
        for info, data in extra:
            zout.writestr(info, data)
    return target


def _spec(write_spec, fmu: Path) -> Path:
    return write_spec({"units": {"o": {"fmu": str(fmu)}}, "experiment": {"stop": 0.2, "step": 0.1},
                       "objectives": {"y": {"signal": "o.y", "reduce": "final"}}})


@pytest.mark.parametrize("kind", ["absolute", "dotdot", "slash"])
def test_a_model_identifier_with_a_path_is_refused(built_fmu, write_spec, tmp_path, kind):
    """The library named by an absolute or relative path exists and would load; cosim refuses it."""
    real = built_fmu("linear_ode", 2)
    folder2, _ = platform_folders()
    outside = tmp_path / "outside"
    outside.mkdir()
    with zipfile.ZipFile(real) as zf:  # a loadable library outside the FMU
        (outside / "linear_ode.so").write_bytes(zf.read(f"binaries/{folder2}/linear_ode.so"))
    identifier = {"absolute": str(outside / "linear_ode"), "dotdot": "../../../outside/linear_ode",
                  "slash": "sub/linear_ode"}[kind]
    # the member the existence check looks for is there too, so only the identifier rule stops it
    member = zipfile.ZipInfo(f"binaries/{folder2}/{identifier}.so")
    fmu = _rewrite(real, tmp_path / "evil.fmu", identifier,
                   extra=[] if kind == "dotdot" else [(member, b"not a library")])
    with pytest.raises(FmuProblems) as caught:
        FmuUnitType(fmu).describe()
    assert "modelIdentifier" in str(caught.value) and "not a plain file name" in str(caught.value)
    done = _cosim("validate", str(_spec(write_spec, fmu)))
    assert done.returncode == 2, done.stderr
    assert "evil.fmu" in done.stderr and "modelIdentifier" in done.stderr and "Traceback" not in done.stderr


def test_the_plain_model_identifier_still_runs(built_fmu, write_spec, tmp_path):
    fmu = _rewrite(built_fmu("linear_ode", 2), tmp_path / "copy.fmu")
    result = cosim.run(str(_spec(write_spec, fmu)))
    assert result.status == "ok", result.message
    assert result.objectives["y"] == pytest.approx(math.exp(-0.2), rel=1e-9)  # x0 = 1, a = -1, u = 0


def _bomb(real: Path, target: Path, megabytes: int) -> Path:
    info = zipfile.ZipInfo("resources/zeros.bin")
    info.compress_type = zipfile.ZIP_DEFLATED
    return _rewrite(real, target, extra=[(info, bytes(megabytes << 20))])


def test_a_zip_bomb_is_refused_before_anything_is_unpacked(built_fmu, write_spec, tmp_path):
    fmu = _bomb(built_fmu("linear_ode", 2), tmp_path / "bomb.fmu", 64)
    assert fmu.stat().st_size < 1 << 20  # 64 MB of zeros compress ~1000 times
    done = _cosim("validate", str(_spec(write_spec, fmu)), env={"COSIM_FMU_RATIO": "100"})
    assert done.returncode == 2, done.stderr
    assert "bomb.fmu" in done.stderr and "more than the limit of 100" in done.stderr
    assert "COSIM_FMU_RATIO" in done.stderr and "Traceback" not in done.stderr
    # raising the limit on purpose lets the same FMU through
    done = _cosim("validate", str(_spec(write_spec, fmu)), env={"COSIM_FMU_RATIO": "5000"})
    assert done.returncode == 0, done.stderr


def test_total_unpacked_size_and_member_count_are_limited(built_fmu, tmp_path, monkeypatch):
    real = built_fmu("linear_ode", 2)
    info = zipfile.ZipInfo("resources/noise.bin")
    fmu = _rewrite(real, tmp_path / "big.fmu", extra=[(info, os.urandom(3 << 20))])  # incompressible 3 MB
    monkeypatch.setenv("COSIM_FMU_UNPACKED_MB", "2")
    with pytest.raises(ArchiveError, match=r"the FMU unpacks to 3\.\d MB, more than the limit of 2\.0 MB"):
        check_archive(fmu)
    monkeypatch.setenv("COSIM_FMU_UNPACKED_MB", "4")
    check_archive(fmu)
    with zipfile.ZipFile(real) as zf:
        members = len(zf.infolist())
    monkeypatch.setenv("COSIM_FMU_MEMBERS", str(members - 1))
    with pytest.raises(FmuProblems, match=f"the FMU has {members} members, more than the limit of {members - 1}"):
        FmuUnitType(real).describe()


def test_extraction_counts_the_bytes_it_writes(built_fmu, tmp_path):
    """Even when the table of contents passes, unpacking stops at the byte limit."""
    fmu = _rewrite(built_fmu("linear_ode", 2), tmp_path / "big.fmu",
                   extra=[(zipfile.ZipInfo("resources/noise.bin"), os.urandom(3 << 20))])
    target = tmp_path / "out"
    check_archive(fmu, ArchiveLimits(max_bytes=4 << 20, max_members=100, max_ratio=1000))
    with pytest.raises(ArchiveError, match="more than the limit of 2.0 MB"):
        safe_extract(fmu, target, ArchiveLimits(max_bytes=2 << 20, max_members=100, max_ratio=1000))
    written = sum(p.stat().st_size for p in target.rglob("*") if p.is_file())
    assert written <= 2 << 20


@pytest.mark.parametrize("mode, word", [(stat.S_IFLNK | 0o777, "symbolic link"),
                                        (stat.S_IFIFO | 0o644, "special file"), (stat.S_IFCHR | 0o644, "special file")])
def test_symlinks_and_special_files_are_refused(built_fmu, tmp_path, mode, word):
    info = zipfile.ZipInfo("resources/link")
    info.create_system = 3
    info.external_attr = mode << 16
    fmu = _rewrite(built_fmu("linear_ode", 3), tmp_path / "link.fmu", extra=[(info, b"/etc/passwd")])
    with pytest.raises(FmuProblems) as caught:
        FmuUnitType(fmu).describe()
    assert caught.value.problems[0].path == "resources/link" and f"is a {word}" in caught.value.problems[0].message
    target = tmp_path / "out"
    with pytest.raises(ArchiveError):
        safe_extract(fmu, target)
    assert not (target / "resources" / "link").exists()


@pytest.mark.parametrize("name", ["../escape.txt", "/tmp/abs.txt", "resources/../../x.txt"])
def test_members_leaving_the_folder_are_refused(built_fmu, tmp_path, name):
    fmu = _rewrite(built_fmu("linear_ode", 3), tmp_path / "escape.fmu", extra=[(zipfile.ZipInfo(name), b"x")])
    with pytest.raises(FmuProblems) as caught:
        FmuUnitType(fmu).describe()
    assert caught.value.problems[0].path == name and "escapes the extraction folder" in str(caught.value)


def test_a_sweep_worker_refuses_an_fmu_the_client_was_allowed_to_use(built_fmu, write_spec, tmp_path, monkeypatch):
    """The limits travel with the payload: a worker child applies the client's limits, not its own."""
    from cosim.parallel.isolation.payload import make_payload
    from cosim.parallel.isolation.runner import IsolatedRunner
    from cosim.system.validate import check_spec

    fmu = _rewrite(built_fmu("linear_ode", 2), tmp_path / "bomb.fmu",
                   extra=[(zipfile.ZipInfo("resources/noise.bin"), os.urandom(8 << 20))])
    system = check_spec(_spec(write_spec, fmu))  # default limits: 8 MB of zeros is fine
    monkeypatch.setenv("COSIM_FMU_UNPACKED_MB", "4")
    payload = make_payload(system)
    monkeypatch.delenv("COSIM_FMU_UNPACKED_MB")
    runner = IsolatedRunner(payload)
    try:
        rows = runner.run([("p1", {})], timeout=60)
    finally:
        runner.close()
    assert rows[0].status == "failed"
    assert "bomb.fmu" in rows[0].message and "more than the limit of 4.0 MB" in rows[0].message
