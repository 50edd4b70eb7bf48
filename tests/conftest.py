"""The test session's own folders. Every ``heliquad board`` a test starts (and every
subprocess, which inherits the environment) announces in the session's folder, never in the
developer's runtime folder, where a real ``--port auto`` would then find test boards. And
matplotlib keeps its configuration and font cache in a folder of the session's: a run killed
while matplotlib wrote the user's font cache once left it without fonts for every later run."""

from __future__ import annotations

import atexit
import os
import shutil
import tempfile

import pytest

from heliquad.sim.rig import announce

# At import, before any test module imports matplotlib (it reads the variable once).
if "MPLCONFIGDIR" not in os.environ:
    os.environ["MPLCONFIGDIR"] = tempfile.mkdtemp(prefix="heliquad-tests-mpl-")
    atexit.register(shutil.rmtree, os.environ["MPLCONFIGDIR"], True)


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
