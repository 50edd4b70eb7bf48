"""The test session's own announcement folder: every ``heliquad board`` a test starts (and
every subprocess, which inherits the environment) announces there, never in the developer's
runtime folder, where a real ``--port auto`` would then find test boards."""

from __future__ import annotations

import os

import pytest

from heliquad.sim.rig import announce


@pytest.fixture(scope="session", autouse=True)
def session_boards_folder(tmp_path_factory):
    """HELIQUAD_BOARDS_DIR set to a folder of the session's for all of it."""
    before = os.environ.get(announce.FOLDER_ENV)
    os.environ[announce.FOLDER_ENV] = str(tmp_path_factory.mktemp("boards") / "announced")
    yield
    if before is None:
        del os.environ[announce.FOLDER_ENV]
    else:
        os.environ[announce.FOLDER_ENV] = before
