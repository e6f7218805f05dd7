"""The tests find the pedscan binary, or fail saying to build it (they never skip)."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

import conftest


def test_no_binary_fails_saying_to_build_it(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("PEDSCAN", raising=False)
    monkeypatch.setattr(conftest, "ROOT", tmp_path)
    with pytest.raises(pytest.fail.Exception, match="build it first"):
        conftest.find_pedscan()


def test_newest_build_is_taken(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("PEDSCAN", raising=False)
    monkeypatch.setattr(conftest, "ROOT", tmp_path)
    for i, kind in enumerate(("debug", "release")):
        (tmp_path / "target" / kind).mkdir(parents=True)
        (tmp_path / "target" / kind / "pedscan").write_text("")
        os.utime(tmp_path / "target" / kind / "pedscan", (1000 - i * 10, 1000 - i * 10))
    assert conftest.find_pedscan() == tmp_path / "target/debug/pedscan"
    monkeypatch.setenv("PEDSCAN", str(tmp_path / "target/release/pedscan"))
    assert conftest.find_pedscan() == tmp_path / "target/release/pedscan"
    monkeypatch.setenv("PEDSCAN", str(tmp_path / "absent"))
    with pytest.raises(pytest.fail.Exception, match="is not a file"):
        conftest.find_pedscan()
