"""Shared fixtures of the Python tests: the repository, its fixtures, and the `crease` binary
the curves are compared with (CREASE_BIN, else the release build that `.ci/run` makes)."""

import os
import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


def _binary() -> Path:
    given = os.environ.get("CREASE_BIN")
    if given:
        return Path(given)
    target = Path(os.environ.get("CARGO_TARGET_DIR", ROOT / "target"))
    found = target / "release" / "crease"
    if found.is_file():
        return found
    on_path = shutil.which("crease")
    return Path(on_path) if on_path else found


@pytest.fixture(scope="session")
def crease_bin() -> Path:
    b = _binary()
    if not b.is_file():
        pytest.fail(f"the crease binary is needed to compare with the command line: build it (cargo build --release) or set CREASE_BIN ({b} not found)")
    return b


@pytest.fixture(scope="session")
def fixtures() -> Path:
    return ROOT / "fixtures"


@pytest.fixture(scope="session")
def cli(crease_bin):
    """Runs the crease binary; returns its completed process, raising with its stderr on failure."""

    def run(*args) -> subprocess.CompletedProcess:
        p = subprocess.run([str(crease_bin), *map(str, args)], capture_output=True, text=True)
        if p.returncode != 0:
            raise AssertionError(f"crease {' '.join(map(str, args))}: exit {p.returncode}: {p.stderr}")
        return p

    return run


@pytest.fixture(scope="session")
def cube_las(cli, tmp_path_factory) -> Path:
    """A synthetic cube of 60 000 points (`crease synth`), as a LAS file."""
    out = tmp_path_factory.mktemp("cube") / "cube.las"
    cli("synth", "shape", "cube", "-n", "60000", "-o", out)
    return out
