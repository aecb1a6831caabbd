"""Where numba keeps the compiled fitter on disk: a folder per version of the package's sources.

numba's cache (`cache=True`) checks only the source file of the function it loads: a compiled function
that calls one from another module (compiled_search's search calls compiled's evaluate, which calls
compiled_kinematics's forward_joints) keeps the old callee when only the callee's file changes, and the
global arrays a compiled function reads (objective's constants, the kinematic chain) keep the values they
had at compilation (numba's documentation, "Cache invalidation"; numba issue #1833). After a change to
compiled.py alone the fitter ran the old objective with the new arguments, silently (session 52). So every module
with compiled code imports this one before its first `@njit(cache=True)`: numba's cache folder (the user's
NUMBA_CACHE_DIR, ./mvpose's .venv/numba-cache, else ~/.cache/mvpose/numba) gets a subfolder named by a digest
of every Python source of mvpose_nodes, and the first start after any change compiles afresh (about 20 s).
Each version's folder takes about 4 MB; the folders of all but the KEPT_VERSIONS most recently used are
removed as a version's folder is first made (other checkouts sharing the cache keep theirs while in use).
"""
import hashlib
import os
import shutil
from pathlib import Path

import numba

PACKAGE = Path(__file__).resolve().parent.parent   # mvpose_nodes/
FOLDER_PREFIX = 'mvpose-'
KEPT_VERSIONS = 4   # version folders kept, this one among them: a few checkouts or branches in turn


def source_digest(package=PACKAGE):
    """A hex digest (16 characters) of the contents of every .py file under `package`, in path order."""
    digest = hashlib.sha256()
    for path in sorted(package.rglob('*.py')):
        digest.update(str(path.relative_to(package)).encode() + b'\0' + path.read_bytes() + b'\0')
    return digest.hexdigest()[:16]


def used_version_folder(base, name, keep=KEPT_VERSIONS):
    """The path of the version folder `name` under `base`, marked as used now (its time set), and the folders
    of other versions (FOLDER_PREFIX*) beyond the `keep` − 1 most recently used removed when it is new. The
    folder itself is left to numba to make. Nothing is raised for a cache that cannot be read or written."""
    folder = Path(base) / name
    try:
        if folder.is_dir():
            os.utime(folder)
            return str(folder)
        others = sorted((path for path in Path(base).glob(FOLDER_PREFIX + '*') if path.is_dir() and path != folder),
                        key=lambda path: path.stat().st_mtime, reverse=True)
    except OSError:
        return str(folder)
    for old in others[keep - 1:]:
        shutil.rmtree(old, ignore_errors=True)
    return str(folder)


# NUMBA_CACHE_DIR as numba read it (./mvpose sets .venv/numba-cache), else the user's cache folder
CACHE_BASE = numba.config.CACHE_DIR or os.path.join(os.path.expanduser('~'), '.cache', 'mvpose', 'numba')
CACHE_FOLDER = used_version_folder(CACHE_BASE, FOLDER_PREFIX + source_digest())   # this version's compiled code
numba.config.CACHE_DIR = CACHE_FOLDER   # read by each @njit(cache=True) as it is decorated
