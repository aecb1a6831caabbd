"""fitting/numba_cache.py: the compiled fitter is cached per version of the package's sources, because numba's
own cache misses changes in a called function's module and in global arrays."""
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
