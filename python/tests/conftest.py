"""Shared fixtures: the repository root, the `meshdeco` binary (for agreement with the command
line) and the real datasets in ../shared/data (skipped with a printed reason when absent; with
CI set, their absence is a failure, as in the Rust tests)."""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
SHARED_DATA = ROOT.parent / "shared" / "data"


def cli_binary() -> Path | None:
    """`$MESHDECO_BIN`, else `<target>/release/meshdeco`, else `meshdeco` on PATH."""
    env = os.environ.get("MESHDECO_BIN")
    if env:
        return Path(env)
    target = Path(os.environ.get("CARGO_TARGET_DIR", ROOT / "target"))
    b = target / "release" / "meshdeco"
    if b.exists():
        return b
    w = shutil.which("meshdeco")
    return Path(w) if w else None


@pytest.fixture
def meshdeco_bin() -> Path:
    b = cli_binary()
    if b is None:
        reason = "the meshdeco binary is not built (cargo build --release) and MESHDECO_BIN is unset"
        if os.environ.get("CI"):
            pytest.fail(f"CI is set but {reason}")
        pytest.skip(reason)
    return b


def shared(name: str) -> Path:
    """A dataset of ../shared/data, or skip (fail with CI set) naming the missing path."""
    p = SHARED_DATA / name
    if not p.exists():
        reason = f"{p} is missing (the real datasets live in ../shared/data beside the clone)"
        if os.environ.get("CI"):
            pytest.fail(f"CI is set but {reason}")
        pytest.skip(reason)
    return p
