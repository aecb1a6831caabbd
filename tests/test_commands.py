"""The commands that work on bags and files offline (no DDS), run as a user runs them: `eval` prints
Table 2, `export` writes CSV, JSON and BVH, `skin train`, `features eval` and `features bench`, and
`markers eval` comparing the three marker methods; their bad input is one line."""
import csv
import json

import cv2
import numpy as np
import pytest
from common import assert_one_line_error, run_mvpose
from rclpy.serialization import serialize_message
from test_export import EPOCH_NS, FRAME_NS, random_model_motion
from test_features import BLUE

from mvpose_nodes.body.model import PARAMETER_NAMES
from mvpose_nodes.io.bagfile import BagWriter
from mvpose_nodes.io.motion_export import read_bvh
from mvpose_nodes.ros.conversions import skeleton_message
from mvpose_nodes.vision.skin import SkinModel

pytestmark = pytest.mark.cli


def test_eval_prints_table_2_for_a_known_offset(tmp_path, cmu_walk):
    motion = cmu_walk
    bag = tmp_path / 'recorded'
    with BagWriter(bag) as out:
        out.add_topic('/mvpose/skeleton', 'mvpose_msgs/msg/Skeleton')
        out.add_topic('/mvpose/ground_truth', 'mvpose_msgs/msg/Skeleton')
        for frame in range(5):
            stamp = 10**18 + frame * 40_000_000
            truth = motion.joints[frame]
            out.write('/mvpose/ground_truth', serialize_message(skeleton_message(truth, stamp)), stamp)
            out.write('/mvpose/skeleton', serialize_message(skeleton_message(truth + [0.010, 0, -0.020], stamp)), stamp)
    table = run_mvpose('eval', bag).stdout
    mean_row = next(line for line in table.splitlines() if line.strip().startswith('mean'))
    cells = mean_row.split()
    assert cells[1].startswith('10.0±0.0') and cells[2].startswith('0.0±0.0') and cells[3].startswith('20.0±0.0')
    assert float(cells[4]) == pytest.approx(np.hypot(10, 20), abs=0.05) and cells[5] == '44.4'
    assert '5 frames matched' in table


def write_skeleton_bag(path, joints, parameters, extra_topics=()):
    """A recorded bag: /mvpose/skeleton with the parameters and a status, /mvpose/ground_truth without
    them (written in reverse order: export sorts by stamp), plus empty extra topics {name: type}."""
    with BagWriter(path) as out:
        out.add_topic('/mvpose/skeleton', 'mvpose_msgs/msg/Skeleton')
        out.add_topic('/mvpose/ground_truth', 'mvpose_msgs/msg/Skeleton')
        for topic, type_name in extra_topics:
            out.add_topic(topic, type_name)
        for frame in range(len(joints)):
            stamp = EPOCH_NS + frame * FRAME_NS
            message = skeleton_message(joints[frame], stamp, parameter_names=list(PARAMETER_NAMES),
                                       parameters=parameters[frame].tolist(), status=frame % 3,
                                       status_message=f'frame {frame}')
            out.write('/mvpose/skeleton', serialize_message(message), stamp)
        for frame in reversed(range(len(joints))):
            stamp = EPOCH_NS + frame * FRAME_NS
            out.write('/mvpose/ground_truth', serialize_message(skeleton_message(joints[frame], stamp)), stamp)


def test_export_command_writes_the_three_formats(tmp_path):
    rng = np.random.default_rng(11)
    parameters, joints = random_model_motion(rng, 6)
    bag = tmp_path / 'recorded'
    write_skeleton_bag(bag, joints, parameters)

    result = run_mvpose('export', bag, '-o', tmp_path / 'out' / 'motion.csv')  # format from the suffix
    assert '6 frames of /mvpose/skeleton' in result.stderr
    rows = list(csv.reader(open(tmp_path / 'out' / 'motion.csv')))
    assert len(rows) == 7 and [row[1] for row in rows[1:]] == ['0', '1', '2', '0', '1', '2']
    np.testing.assert_allclose(np.array([row[47:] for row in rows[1:]], dtype=float), parameters, atol=1e-9)

    run_mvpose('export', bag, '--format', 'json', '-o', tmp_path / 'truth.txt', '--topic', '/mvpose/ground_truth')
    document = json.loads((tmp_path / 'truth.txt').read_text())
    assert document['source']['topic'] == '/mvpose/ground_truth'
    assert [f['stamp_ns'] for f in document['frames']] == [EPOCH_NS + k * FRAME_NS for k in range(6)]
    np.testing.assert_allclose([f['joints'] for f in document['frames']], joints, atol=1e-12)
    assert all(f['parameters'] is None for f in document['frames'])

    result = run_mvpose('export', bag, '--format', 'bvh', '-o', tmp_path / 'motion.bvh')
    assert 'frame time 40.0 ms' in result.stderr and 'within 0.000 mm' in result.stderr
    back, frame_time = read_bvh(tmp_path / 'motion.bvh')
    assert np.abs(back - joints).max() < 1e-6 and frame_time == pytest.approx(0.04)


def test_export_bad_input_is_a_one_line_error(tmp_path):
    rng = np.random.default_rng(5)
    parameters, joints = random_model_motion(rng, 2)
    bag = tmp_path / 'recorded'
    write_skeleton_bag(bag, joints, parameters, extra_topics=[('/camera_pose', 'geometry_msgs/msg/PoseStamped')])
    existing = tmp_path / 'existing.csv'
    existing.write_text('keep me\n')

    def error(*args):
        return run_mvpose('export', *args, check=False)
    assert_one_line_error(error(tmp_path / 'nowhere', '--format', 'csv', '-o', tmp_path / 'a.csv'),
                          str(tmp_path / 'nowhere'), 'no such file')
    assert_one_line_error(error(bag, '--topic', '/nothing', '-o', tmp_path / 'a.csv'), str(bag), '/nothing')
    assert_one_line_error(error(bag, '--topic', '/camera_pose', '-o', tmp_path / 'a.csv'),
                          '/camera_pose', 'geometry_msgs/msg/PoseStamped', 'not mvpose_msgs/msg/Skeleton')
    assert_one_line_error(error(bag, '--format', 'fbx', '-o', tmp_path / 'a.fbx'), "invalid choice: 'fbx'")
    assert_one_line_error(error(bag, '-o', tmp_path / 'a.txt'), '--format')
    assert_one_line_error(error(bag, '-o', existing), str(existing), 'already exists', 'another -o')
    assert existing.read_text() == 'keep me\n'
    assert not (tmp_path / 'a.csv').exists()


def test_skin_train_command_and_its_errors(tmp_path):
    folder = tmp_path / 'pairs'
    folder.mkdir()
    image = np.full((60, 80, 3), BLUE[::-1], np.uint8)
    image[20:40, 30:50] = (110, 140, 200)  # BGR skin-like patch
    mask = np.zeros((60, 80), np.uint8)
    mask[20:40, 30:50] = 255
    cv2.imwrite(str(folder / 'a.png'), image)
    cv2.imwrite(str(folder / 'a_skin.png'), mask)
    run_mvpose('skin', 'train', folder, '-o', tmp_path / 'model.npz')
    model = SkinModel.load(tmp_path / 'model.npz')
    assert model.skin_counts.sum() == 400
    assert model.likelihood(cv2.cvtColor(image, cv2.COLOR_BGR2RGB))[30, 40] > 0
    assert_one_line_error(run_mvpose('skin', 'train', tmp_path / 'nothing', '-o', tmp_path / 'x.npz', check=False),
                          'nothing')
    assert_one_line_error(run_mvpose('skin', 'train', '-o', tmp_path / 'x.npz', check=False), '--studio')
    assert_one_line_error(run_mvpose('skin', 'train', '--studio', -1, '-o', tmp_path / 'x.npz', check=False),
                          '--studio')


def test_skin_train_on_studio_renders_learns_their_skin_and_hair(tmp_path):
    """`skin train --studio 1` renders one person drawn as the suite draws them, from its first 3 cameras
    at 2 instants, and counts the skin as skin and the rest of the person (hair, clothes) and the band
    around it as non-skin: on the first of those images, the model calls skin most skin pixels and hardly
    any of the hair above the face."""
    from mvpose_nodes.app.skin import DEFAULT_STUDIO_SEED, STUDIO_CAMERAS, STUDIO_FRAMES, studio_pairs
    result = run_mvpose('skin', 'train', '--studio', 1, '-j', 1, '-o', tmp_path / 'model.npz', timeout=180)
    assert f'{STUDIO_CAMERAS * STUDIO_FRAMES} images' in result.stderr
    model = SkinModel.load(tmp_path / 'model.npz')
    rgb, skin, person = next(studio_pairs(0, DEFAULT_STUDIO_SEED))
    assert model.skin_counts.sum() >= np.count_nonzero(skin) > 0
    likelihood = model.likelihood(rgb)
    assert np.mean(likelihood[skin] > 0) > 0.9
    hair = person & (np.arange(len(rgb))[:, None] < np.flatnonzero(skin.any(axis=1))[0])   # above the face
    assert hair.any() and np.mean(likelihood[hair] > 0) < 0.1


def test_eval_and_bench_commands_print_their_tables(synth_bag):
    bag = synth_bag('--cameras', 5, '--frames', '70-71', '--resolution', '640x360')
    table = run_mvpose('features', 'eval', bag).stdout
    assert 'silhouette IoU' in table and 'skin' in table and 'contour labels' in table
    head_row = next(line for line in table.splitlines() if line.split()[:1] == ['head'])
    assert head_row.split()[1] == '2/2'
    bench = run_mvpose('features', 'bench', bag).stdout
    assert 'pipeline (all stages)' in bench and 'JPEG decode' in bench


def test_markers_eval_compares_the_three_methods(tmp_path, synth_bag):
    """`./mvpose markers eval` on a short marker bag prints a row per method, the fused one from the same
    code as the graph; a bag without markers is refused in one line naming it."""
    bag = synth_bag('--markers', '--cameras', 3, 5, 7, '--frames', '60-63', '--resolution', '960x540')
    out = run_mvpose('markers', 'eval', bag, '--pictures', tmp_path / 'pictures', timeout=300).stdout
    totals = out[out.index('  totals'):].splitlines()[1:4]
    rows = {line[:25].strip(): [float(v) for v in line[25:].replace('/', ' ').split()] for line in totals}
    assert set(rows) == {'nearest neighbour', 'regions (paper 001)', 'regions + 3D fusion'}, out
    # What the views buy: the fused 3D markers are nearer the truth than either method's own triangulation.
    visible, hidden, swaps, mean_3d, max_3d = rows['regions + 3D fusion']
    assert 0 <= visible < 5 and mean_3d < min(rows['nearest neighbour'][3], rows['regions (paper 001)'][3]), out
    # The pictures: a tile per camera, the detected markers' green dots on them.
    import cv2
    pictures = sorted((tmp_path / 'pictures').glob('markers_frame*_*.png'))
    assert [p.name.rsplit('_', 1)[-1] for p in pictures].count('worst.png') == 1 and len(pictures) == 2, out
    for picture in pictures:
        assert f'wrote {picture}' in out
        rgb = cv2.cvtColor(cv2.imread(str(picture)), cv2.COLOR_BGR2RGB)
        assert rgb.shape[1] == 3 * 560
        assert np.sum(np.all(np.abs(rgb.astype(int) - (60, 220, 60)) < 12, axis=2)) > 3 * 50
    plain = synth_bag('--cameras', 3, 5, '--frames', '60-60', '--resolution', '480x270')
    result = run_mvpose('markers', 'eval', plain, check=False)
    assert result.returncode != 0
    assert f"bag '{plain}' has no ground-truth markers" in result.stderr and len(result.stderr.strip().splitlines()) == 1


def test_eval_suite_runs_small_cases_and_prints_every_figure(tmp_path):
    """Issue 13's small suite for CI: 3 drawn cases at 960×540, 10 frame sets each, fitted as the node
    fits them; the table has a row per case, a summary per motion set, and the worst case's pictures, and
    cases.json the same figures. The same draw twice gives the same table (the suite is deterministic), the
    second time from the features cache the first run wrote, and `eval compare` finds no difference."""
    cache = tmp_path / 'cache'
    arguments = ('eval', 'suite', '--cases', 3, '--frames', 10, '--resolution', '960x540', '--seed', 4,
                 '--features-cache', cache, '-o', tmp_path / 'suite')
    first = run_mvpose(*arguments, timeout=600)
    assert len(list(cache.glob('*.pkl'))) == 3 and not list(cache.glob('*.partial'))
    rows = [line for line in first.stdout.splitlines() if line[:5].strip().isdigit()]
    assert len(rows) == 3, first.stdout
    for row in rows:
        mean, median, worst = (float(cell) for cell in row.split()[-6:-3])
        assert 0 < median <= worst and mean <= worst, row
    assert 'per joint (all cases): pelvis' in first.stdout
    assert any(line.strip().startswith(('tuning:', 'held-out:', 'stress:')) and '90th percentile' in line
               for line in first.stdout.splitlines()), first.stdout
    assert len(list((tmp_path / 'suite').glob('worst_case_*_error_per_frame.png'))) == 1
    assert len(list((tmp_path / 'suite').glob('worst_case_*_frame_*.png'))) == 1
    figures = json.loads((tmp_path / 'suite' / 'cases.json').read_text())
    assert figures['run']['seed'] == 4 and [case['index'] for case in figures['cases']] == [0, 1, 2]
    assert [[f'{case[key]:.1f}' for key in ('mean', 'median', 'worst')] for case in figures['cases']] == [
        row.split()[-6:-3] for row in rows], 'the table\'s figures'
    cached = {path: path.stat().st_mtime_ns for path in cache.glob('*.pkl')}
    again = run_mvpose(*arguments[:-1], tmp_path / 'again', '--only', 1, timeout=600)
    repeated = [line for line in again.stdout.splitlines() if line[:5].strip() == '1']
    assert [line.rsplit(maxsplit=1)[0] for line in repeated] == [rows[1].rsplit(maxsplit=1)[0]]   # all but fit ms
    compared = run_mvpose('eval', 'compare', '--before', tmp_path / 'suite', '--after', tmp_path / 'again').stdout
    assert '1 case run before and after (2 run on one side only, left out)' in compared
    assert '+0.0 [+0.0, +0.0]' in compared and 'moved most' not in compared, compared
    assert {path: path.stat().st_mtime_ns for path in cache.glob('*.pkl')} == cached, 'read, not written again'
    gapped = run_mvpose(*arguments[:-1], tmp_path / 'gapped', '--only', 1, '--gaps', 2, 3, timeout=600)
    assert 'one frame set in every 2 or 3 (--gaps)' in gapped.stderr
    row = next(line for line in gapped.stdout.splitlines() if line[:5].strip() == '1')
    assert row.split()[-2] == '0', 'the frame sets passed over are not counted as unanswered'


def test_the_suite_passes_over_frame_sets_in_the_steps_it_is_given():
    from mvpose_nodes.app.suite import passed_over_by
    passed_over = passed_over_by(200, [1, 2, 2, 3], seed=5)
    fitted = np.flatnonzero(~passed_over)
    assert fitted[0] == 0 and set(np.diff(fitted)) == {1, 2, 3}
    assert np.array_equal(passed_over, passed_over_by(200, [1, 2, 2, 3], seed=5))
    assert not passed_over_by(10, [1], seed=0).any()
    assert np.flatnonzero(~passed_over_by(10, [4], seed=0)).tolist() == [0, 4, 8]


def test_the_suite_keeps_each_window_in_view():
    """A run crosses a ring in two seconds: its windows are shortened until every frame shows the whole person
    to MIN_FULL_VIEWS cameras, and no further (one frame more would not); a turn on the spot keeps its 50."""
    from types import SimpleNamespace
    from mvpose_nodes.app import suite
    from mvpose_nodes.app.suite import features as suite_features
    from mvpose_nodes.studio.cases import MIN_FULL_VIEWS, full_views
    from mvpose_nodes.studio.catalogue import load_motion
    runs = suite.draw_cases(SimpleNamespace(motions='amp_run', seed=1, frames=50, cameras=None, cases=4),
                            (1920, 1080))
    assert any(case.frames < 50 for case in runs)
    for case in runs:
        assert (full_views(case, suite_features.case_motion(case).joints) >= MIN_FULL_VIEWS).all(), case.index
        if case.frames < 50:
            longer = suite_features.placed_window(load_motion(case.motion, height=case.height), case, case.frames + 1)
            assert (full_views(case, longer.joints) < MIN_FULL_VIEWS).any(), case.index
    turns = suite.draw_cases(SimpleNamespace(motions='turn_on_the_spot', seed=1, frames=50, cameras=None, cases=3),
                             (1920, 1080))
    assert [case.frames for case in turns] == [50, 50, 50]


def test_suite_features_cache_reads_back_what_it_wrote_and_recomputes_a_damaged_file(tmp_path, capsys,
                                                                                     monkeypatch):
    from types import SimpleNamespace
    from mvpose_nodes.app import suite
    from mvpose_nodes.app.suite import features as suite_features
    args = SimpleNamespace(motions='tuning', seed=3, frames=2, cameras=[3, 5], cases=1)
    [case] = suite.draw_cases(args, (480, 270))
    motion = suite_features.case_motion(case)

    computed = suite_features.case_features(case, motion)   # the messages as the node gets them: float32 fields rounded
    assert len(computed) == 2 and set(computed[0][1]) == {3, 5}
    confidence = computed[0][1][3][0].face_visibility
    assert 0 < confidence < 1 and confidence == np.float32(confidence), 'serialised and read back'
    assert suite_features.case_features(case, motion, tmp_path) == computed
    [stored] = tmp_path.glob('*.pkl')
    with monkeypatch.context() as patch:
        patch.setattr(suite_features, 'render_camera', lambda *_: pytest.fail('rendered again: the cache was not read'))
        assert suite_features.case_features(case, motion, tmp_path) == computed
    stored.write_bytes(b'not a pickle')
    assert suite_features.case_features(case, motion, tmp_path) == computed
    assert 'unreadable' in capsys.readouterr().err and stored.read_bytes() != b'not a pickle'


def test_eval_suite_bad_arguments_are_one_line_errors():
    assert_one_line_error(run_mvpose('eval', 'suite', '--motions', 'moonwalk', check=False), 'moonwalk')
    assert_one_line_error(run_mvpose('eval', 'suite', '--cameras', 3, 3, check=False), '--cameras')
    assert_one_line_error(run_mvpose('eval', 'suite', '--cases', 2, '--only', 5, check=False), '--only')
