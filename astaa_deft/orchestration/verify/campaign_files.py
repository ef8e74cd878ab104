"""A campaign folder's files as data: module tests found only inside it, copied as data, run with the user's spec.

A campaign folder travels (CI artefacts, a colleague's results, a bug
report), so what its journal names is data. ``verify`` and ``export`` copy a
bucket's DeFT module tests and run them; here that is made safe:

* the folder a journal row names (``minimisations.tests_dir``,
  ``module_tests.tests_dir``) must resolve inside the campaign folder — a
  path or a link out of it is refused (``InputError`` naming the row);
* only the suite's data is copied — its manifest and its frames, each a
  regular file (no link, no ``conftest.py``, no test module of its own) —
  and the copy gets the tool's own ``pytest.ini``;
* the copied manifest embeds the spec the user gave the command, so the
  replay builds the module the user's spec names (its factory, its command),
  never one named only in the copy.
"""

from __future__ import annotations

import errno
import json
import os
import shutil
import stat
from collections.abc import Mapping
from pathlib import Path
from typing import BinaryIO

from astaa_deft.analysis.deft.export import FRAMES, MANIFEST, PYTEST_INI, PYTEST_INI_TEXT, oracles_of
from astaa_deft.io.output_place import write_atomic
from astaa_deft.io.statefile import StateReader, load_json
from astaa_deft.model.errors import InputError, Problem
from astaa_deft.model.sut import Spec

MAX_MANIFEST_BYTES = 64 << 20  # a DeFT suite's deft.json: far above a real one (a few MB for thousands of frames)
_FIX = "re-run the campaign (astaa-deft fuzz), or verify the buckets without module tests (--bucket)"


def tests_dir_inside(campaign: Path, text: str | None, *, journal: Path, field: str) -> Path | None:
    """The DeFT suite folder a journal row names, resolved; None when the row names none, it is gone, or it
    holds no DeFT suite (a module-level finding's generated test: code, never copied or run from a campaign).

    InputError when it resolves outside ``campaign`` (through ``..``, an absolute path or a link): module tests
    are copied and run only from inside the campaign folder.
    """
    if not text:
        return None
    path = Path(text)
    root = campaign.resolve()
    real = (path if path.is_absolute() else root / path).resolve()
    if real != root and root not in real.parents:
        raise InputError(Problem(str(journal), None, None,
                                 f"{field} names {text[:200]!r}, outside the campaign folder {root}: module tests "
                                 f"are copied and run only from inside the campaign", _FIX))
    return real if real.is_dir() and (real / MANIFEST).is_file() and not (real / MANIFEST).is_symlink() else None


def _open_regular(path: Path) -> BinaryIO:
    """``path`` opened for reading when it is a regular file — not a link (never followed), a folder or a
    device — else InputError."""
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK)
    except OSError as exc:
        why = "is a link: module tests are copied only as files" if exc.errno == errno.ELOOP else \
            f"cannot be read: {exc.strerror or exc}"
        raise InputError(Problem(str(path), None, None, why, _FIX)) from None
    if not stat.S_ISREG(os.fstat(fd).st_mode):
        os.close(fd)
        raise InputError(Problem(str(path), None, None, "is not a regular file (a folder or a device): module "
                                 "tests are copied only as files", _FIX))
    return os.fdopen(fd, "rb")


def suite_manifest(suite: Path) -> dict[str, object]:
    """A DeFT suite's manifest (``deft.json``) as a JSON object, size-capped; InputError when it is none."""
    path = suite / MANIFEST
    with _open_regular(path) as f:
        data = f.read(MAX_MANIFEST_BYTES + 1)
    if len(data) > MAX_MANIFEST_BYTES:
        raise InputError(Problem(str(path), None, None, f"is over {MAX_MANIFEST_BYTES >> 20} MiB: not a module "
                                 "test manifest the tool writes", _FIX))
    value = StateReader(str(path), load_json(data, str(path), "", _FIX), _FIX).obj().json_object()
    return dict(value)


def has_oracles(suite: Path) -> bool:
    """Whether the suite holds oracle tests (the replayed module breaks the bucket's invariant)."""
    try:
        return bool(oracles_of(suite_manifest(suite)))
    except InputError:
        return False


def copy_module_suite(source: Path, target: Path, spec: Spec, *, params: Mapping[str, str] | None = None) -> None:
    """Copy the DeFT suite in ``source`` to ``target`` (new) as data (module doc), its manifest given ``spec``
    and ``params`` overriding its params. InputError when ``source`` is not a suite of plain files."""
    manifest = suite_manifest(source)
    manifest["spec_yaml"] = spec.source_text
    manifest["spec_name"] = spec.name
    manifest["spec_dir"] = str(spec.path.resolve().parent) if spec.path is not None else None
    recorded = manifest.get("params")
    manifest["params"] = {**(recorded if isinstance(recorded, dict) else {}), **(params or {})}
    target.mkdir(parents=True)
    with _open_regular(source / FRAMES) as frames, open(target / FRAMES, "xb") as copy:
        shutil.copyfileobj(frames, copy)
    write_atomic(target / MANIFEST, json.dumps(manifest, indent=1) + "\n")
    write_atomic(target / PYTEST_INI, PYTEST_INI_TEXT)
