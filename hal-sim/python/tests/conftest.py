"""Shared fixtures: where the repository, the `regen` binary and the EMPS data are."""

import os
import pathlib
import shutil
import subprocess

import pytest

REPO = pathlib.Path(__file__).resolve().parents[3]
EMPS = REPO / "data" / "emps"


def _regen_bin():
    env = os.environ.get("REGEN_BIN")
    if env:
        return env
    for p in (REPO / "target" / "release" / "regen", REPO / "target" / "debug" / "regen"):
        if p.exists():
            return str(p)
    return shutil.which("regen")


@pytest.fixture(scope="session")
def regen():
    """Run the `regen` command line; returns (exit code, stdout, stderr)."""
    exe = _regen_bin()
    if exe is None:
        msg = "no `regen` binary (set REGEN_BIN or `cargo build -p hal-sim --bin regen`)"
        print(f"SKIP: {msg}")
        pytest.skip(msg)

    def run(*args, cwd=None):
        p = subprocess.run([exe, *map(str, args)], capture_output=True, text=True,
                           cwd=cwd or REPO, timeout=600)
        return p.returncode, p.stdout, p.stderr

    return run


def cli_error(stderr: str) -> str:
    """The message `regen` prints on refusal (`error: MSG`, MSG possibly several lines)."""
    k = stderr.find("error: ")
    while k > 0 and stderr[k - 1] != "\n":
        k = stderr.find("error: ", k + 1)
    assert k >= 0, f"no error line in: {stderr!r}"
    return stderr[k + len("error: "):].removesuffix("\n")
