"""fitting/numba_cache.py: the compiled fitter is cached per version of the package's sources, because numba's
own cache misses changes in a called function's module and in global arrays."""
import os

import pytest

from mvpose_nodes.fitting import numba_cache

pytestmark = pytest.mark.pure


def test_the_digest_changes_with_any_source_and_only_with_the_sources(tmp_path):
    (tmp_path / 'fitting').mkdir()
    (tmp_path / 'fitting' / 'compiled.py').write_text('WEIGHTS = (1.0, 2.0)\n')
    (tmp_path / 'objective.py').write_text('RADIUS = 0.13\n')
    (tmp_path / 'notes.txt').write_text('not a source\n')
    first = numba_cache.source_digest(tmp_path)
    assert numba_cache.source_digest(tmp_path) == first and len(first) == 16
    (tmp_path / 'notes.txt').write_text('changed\n')
    assert numba_cache.source_digest(tmp_path) == first
    (tmp_path / 'objective.py').write_text('RADIUS = 0.14\n')   # a constant a compiled function reads
    second = numba_cache.source_digest(tmp_path)
    assert second != first
    (tmp_path / 'objective.py').rename(tmp_path / 'fitting' / 'objective.py')
    assert numba_cache.source_digest(tmp_path) not in (first, second)


def test_every_compiled_function_is_cached_in_this_versions_folder():
    from mvpose_nodes.fitting import compiled, compiled_kinematics, compiled_search
    folder = numba_cache.CACHE_FOLDER
    assert folder.endswith('mvpose-' + numba_cache.source_digest())
    functions = [compiled.evaluate, compiled.outline_nearest, compiled_kinematics.forward_joints,
                 compiled_search.search, compiled_kinematics.limb_excess]
    for function in functions:
        assert function._cache._cache_path.startswith(folder + '/'), function


def test_a_new_versions_folder_removes_all_but_the_most_recently_used_others(tmp_path):
    for age, name in enumerate('abcdef'):   # mvpose-f used last
        (tmp_path / f'mvpose-{name}').mkdir()
        os.utime(tmp_path / f'mvpose-{name}', (1000.0 + age, 1000.0 + age))
    (tmp_path / 'unrelated').mkdir()
    folder = numba_cache.used_version_folder(tmp_path, 'mvpose-new', keep=4)
    assert folder == str(tmp_path / 'mvpose-new')   # numba makes it
    assert sorted(p.name for p in tmp_path.iterdir()) == ['mvpose-d', 'mvpose-e', 'mvpose-f', 'unrelated']
    # An existing version's folder is marked as used, and nothing is removed.
    assert numba_cache.used_version_folder(tmp_path, 'mvpose-d', keep=1) == str(tmp_path / 'mvpose-d')
    assert (tmp_path / 'mvpose-d').stat().st_mtime > (tmp_path / 'mvpose-f').stat().st_mtime
    assert sorted(p.name for p in tmp_path.iterdir()) == ['mvpose-d', 'mvpose-e', 'mvpose-f', 'unrelated']
