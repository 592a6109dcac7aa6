"""Stale compiled kernels: purge numba's on-disk cache when the solver's source changes.

numba keys a cached kernel (``cache=True``) on its own source file only. A kernel that
calls a kernel of another module (the residual calls the contact evaluation, Newton
calls the residual) compiles the callee into itself, so after the callee's file changes
the caller's cache still holds the old callee: it loads and runs stale machine code
(seen once: an out-of-bounds loop fixed in ``solver/contact/model.py`` went on running
inside ``solver/scheme.py``'s cached residual). :func:`purge_stale` fingerprints every
source file of the package and deletes the package's cache files (``*.nbi``, ``*.nbc``
in its ``__pycache__`` folders, and under ``NUMBA_CACHE_DIR`` when that is set) when the
fingerprint differs from the one stored with them; the kernels are then compiled afresh
once. It runs when :mod:`solver` is imported, before any kernel is loaded.
"""
from __future__ import annotations

import hashlib
import os
from pathlib import Path

_ROOT = Path(__file__).resolve().parent
_STAMP = "hockle-kernels.sha256"


def fingerprint() -> str:
    """SHA-256 (hex) of the package's Python sources, names and contents."""
    h = hashlib.sha256()
    for f in sorted(_ROOT.rglob("*.py")):
        h.update(f.relative_to(_ROOT).as_posix().encode())
        h.update(f.read_bytes())
    return h.hexdigest()


def _user_cache_dirs() -> list[Path]:
    """The folders under ``NUMBA_CACHE_DIR`` (none when it is unset) where numba keeps this
    package's kernels: one per source folder, named by numba after the folder and the
    SHA-1 of its path (``solver_<sha1>``, ``contact_<sha1>``, ...;
    ``numba.core.caching.UserProvidedCacheLocator.get_suitable_cache_subpath``), whether
    or not they exist yet."""
    user = os.environ.get("NUMBA_CACHE_DIR")
    if not user:
        return []
    try:
        from numba.core.caching import UserProvidedCacheLocator
    except ImportError:
        return []
    folders = sorted({f.parent for f in _ROOT.rglob("*.py")})
    return [Path(user) / UserProvidedCacheLocator.get_suitable_cache_subpath(str(d / "_.py"))
            for d in folders]


def _cache_dirs() -> list[Path]:
    """Every folder that may hold this package's cache files: its ``__pycache__`` folders
    and its folders under ``NUMBA_CACHE_DIR`` (:func:`_user_cache_dirs`)."""
    return list(_ROOT.rglob("__pycache__")) + [d for d in _user_cache_dirs() if d.is_dir()]


def kernels_cached() -> bool:
    """Whether numba's on-disk cache holds compiled kernels of this package: under
    ``NUMBA_CACHE_DIR`` when it is set (numba then reads only there), else in the
    package's ``__pycache__`` folders. After :func:`purge_stale` has run (at the import
    of :mod:`solver`) these are kernels of the current sources."""
    dirs = _user_cache_dirs() if os.environ.get("NUMBA_CACHE_DIR") else list(
        _ROOT.rglob("__pycache__"))
    return any(next(d.glob("*.nbi"), None) is not None for d in dirs if d.is_dir())


def purge_stale() -> bool:
    """Delete the package's numba cache files if the sources changed since they were
    written; returns whether it purged. Never raises for file-system trouble (a cache
    that cannot be checked is left to numba)."""
    try:
        digest = fingerprint()
        stamp = _ROOT / "__pycache__" / _STAMP
        if stamp.is_file() and stamp.read_text() == digest:
            return False
        for d in _cache_dirs():
            for f in list(d.glob("*.nbi")) + list(d.glob("*.nbc")):
                f.unlink(missing_ok=True)
        stamp.parent.mkdir(exist_ok=True)
        tmp = stamp.with_name(f"{_STAMP}.{os.getpid()}")
        tmp.write_text(digest)
        os.replace(tmp, stamp)
        return True
    except OSError:
        return False
