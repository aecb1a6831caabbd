"""`eval compare` (app/compare.py): two `eval suite` runs paired case by case, and the bootstrap interval of
the mean difference (app/reports/accuracy.paired_difference), on constructed figures."""
import json

import numpy as np
import pytest
from common import assert_one_line_error, run_mvpose

from mvpose_nodes.app.reports.accuracy import paired_difference


@pytest.mark.pure
def test_paired_difference_is_the_mean_change_with_an_interval_that_shows_what_it_rests_on():
    rng = np.random.default_rng(3)
    before = rng.uniform(30, 200, 40)
    assert paired_difference(before, before) == (0.0, 0.0, 0.0)
    mean, low, high = paired_difference(before, before + 5.0)
    assert mean == pytest.approx(5.0) and low == pytest.approx(5.0) and high == pytest.approx(5.0)
    # One case of 40 moved by 300 mm (a fit turned round), the rest not at all: a mean change of 7.5 mm that
    # the interval shows rests on that one case (its lower end 0: resamples without it).
    after = before.copy()
    after[7] += 300.0
    mean, low, high = paired_difference(before, after)
    assert mean == pytest.approx(7.5) and low == 0.0 and high > 15.0
    assert paired_difference(before, after) == (mean, low, high), 'seeded: the same figures, the same interval'
    # Many small changes the same way: an interval that excludes 0.
    mean, low, high = paired_difference(before, before - rng.uniform(1.0, 3.0, 40))
    assert high < 0 and low < mean < high
    with pytest.raises(ValueError, match='same N > 0'):
        paired_difference(before, before[:-1])


def suite_run(folder, seed, means, swaps=None, motion='07_01 0–49 heading 10°'):
    """An `eval suite` output folder with cases.json: case i with mean error means[i] (None: no skeleton)."""
    folder.mkdir(parents=True, exist_ok=True)
    cases = [{'index': i, 'set': 'tuning' if i % 3 else 'held-out', 'motion': f'{motion} #{i}', 'rig': 'Ø8.0 m',
              'body': '1.75 m', 'imaging': 'jpeg 90', 'mean': mean, 'median': mean, 'worst': mean,
              'swaps': (swaps or [0] * len(means))[i], 'none': 0 if mean is not None else 50, 'fit_ms': 30.0}
             for i, mean in enumerate(means)]
    (folder / 'cases.json').write_text(json.dumps({'run': {'seed': seed}, 'cases': cases}))
    return folder


@pytest.mark.cli
def test_eval_compare_pairs_the_cases_of_the_same_draws_and_says_what_moved(tmp_path):
    """Two seeds on each side, one case more after than before (left out and said); per motion set and for
    all: the cases, the means and medians, the paired difference with its interval, the cases moved either
    way, those within 44.4 mm and the swaps; then the cases that moved most, largest first."""
    before = [suite_run(tmp_path / 'b1', 1, [40.0, 60.0, 300.0]), suite_run(tmp_path / 'b2', 2, [50.0, 42.0, 90.0])]
    after = [suite_run(tmp_path / 'a1', 1, [40.0, 61.0, 60.0], swaps=[0, 0, 4]),
             suite_run(tmp_path / 'a2', 2, [50.0, 80.0, 90.0, 35.0])]
    out = run_mvpose('eval', 'compare', '--before', *before, '--after', *after).stdout
    assert '6 cases run before and after (1 run on one side only, left out)' in out, out
    rows = {line.split()[0]: line for line in out.splitlines() if line.startswith('  ') and line.split()[0] in
            ('tuning', 'held-out', 'all')}
    assert rows['all'].split()[1:8] == ['6', '97.0', '/', '55.0', '63.5', '/', '60.5'], out
    assert '-33.5 [' in rows['all'] and '1 / 1' in rows['all'] and '2 -> 1' in rows['all'] and '0 -> 4' in rows['all'], out
    assert rows['held-out'].split()[1] == '2' and '+0.0 [+0.0, +0.0]' in rows['held-out'], out
    moved = out[out.index('moved most'):].splitlines()[1:]
    assert [line.split()[1:4] for line in moved] == [['1', 'case', '2'], ['2', 'case', '1'], ['1', 'case', '1']], out
    assert '300.0 ->   60.0 (-240.0)  swaps 0 -> 4' in moved[0], out


@pytest.mark.cli
def test_eval_compare_refuses_what_it_cannot_pair_in_one_line(tmp_path):
    good = suite_run(tmp_path / 'good', 1, [40.0, 50.0])
    missing = tmp_path / 'nowhere'
    assert_one_line_error(run_mvpose('eval', 'compare', '--before', good, '--after', missing, check=False),
                          f"'{missing}': no such file")
    (tmp_path / 'broken.json').write_text('{"cases": [')
    assert_one_line_error(run_mvpose('eval', 'compare', '--before', good, '--after', tmp_path / 'broken.json',
                                     check=False), f"'{tmp_path / 'broken.json'}': not an `eval suite` cases.json")
    other = suite_run(tmp_path / 'other', 1, [40.0, 50.0], motion='amp_run 3–52 heading 90°')
    assert_one_line_error(run_mvpose('eval', 'compare', '--before', good, '--after', other, check=False),
                          'case 0 of seed 1 is not the same case before and after (motion:')
    elsewhere = suite_run(tmp_path / 'elsewhere', 5, [40.0])
    assert_one_line_error(run_mvpose('eval', 'compare', '--before', good, '--after', elsewhere, check=False),
                          'the two sides have no case in common')
    assert_one_line_error(run_mvpose('eval', 'compare', '--before', good, good, '--after', good, check=False),
                          'case 0 of seed 1 is already in an earlier run on this side')
