"""One parameter mechanism for the four nodes (ros/params.py): the tables agree with config/*.yaml, the
checks refuse bad values in one line, and a running skeleton_fitter exposes the fitter's settings as
described, ranged, read-only parameters over DDS."""
import math
from pathlib import Path

import pytest
import rclpy
import yaml
from common import assert_one_line_error, run_mvpose
from rcl_interfaces.msg import ParameterType
from rcl_interfaces.srv import DescribeParameters, GetParameters

from mvpose_nodes.fitting.settings import SETTING_FIELDS, FitterSettings
from mvpose_nodes.ros.params import (CAMERA_FEATURES, MARKER_SKELETON, MARKER_TRACKER, SKELETON_FITTER, Parameter,
                                     ParameterError, check, fitter_settings_from, load_parameters)

pytestmark = pytest.mark.dds

CONFIG = Path(__file__).resolve().parent.parent / 'ros_ws' / 'src' / 'mvpose_nodes' / 'config'
TABLES = {'camera_features': CAMERA_FEATURES, 'marker_tracker': MARKER_TRACKER,
          'skeleton_fitter': SKELETON_FITTER, 'marker_skeleton': MARKER_SKELETON}


@pytest.mark.parametrize('executable', TABLES)
def test_the_config_file_of_each_node_holds_exactly_its_table_defaults(executable):
    values = yaml.safe_load((CONFIG / f'{executable}.yaml').read_text())['/**']['ros__parameters']
    assert values == {p.name: p.default for p in TABLES[executable]}
    assert load_parameters(CONFIG / f'{executable}.yaml', TABLES[executable], executable) == values


@pytest.mark.parametrize('executable', TABLES)
def test_every_parameter_has_a_description_and_numbers_have_a_range(executable):
    for parameter in TABLES[executable]:
        assert len(parameter.description) > 15, parameter.name
        if isinstance(parameter.default, (int, float, list)) and not isinstance(parameter.default, bool):
            assert parameter.range, parameter.name


def test_the_fitter_settings_are_the_skeleton_fitter_parameters_and_come_back_unchanged():
    names = [p.name for p in SKELETON_FITTER]
    assert [f.name for f in SETTING_FIELDS] == names[-len(SETTING_FIELDS):]
    defaults = {p.name: p.default for p in SKELETON_FITTER}
    assert fitter_settings_from(defaults) == FitterSettings()
    assert fitter_settings_from({**defaults, 'max_evaluations_per_parameter': 10}).max_evaluations_per_parameter == 10


@pytest.mark.parametrize('parameter, value, problem', [
    (Parameter('cameras', [3, 5, 7], 'd', range=(1, 99), distinct=True), [3, 3], 'distinct'),
    (Parameter('cameras', [3, 5, 7], 'd', range=(1, 99), distinct=True), [3, 100], 'in [1, 99]'),
    (Parameter('cameras', [3, 5, 7], 'd', range=(1, 99), distinct=True), [], 'non-empty list of integers'),
    (Parameter('cameras', [3, 5, 7], 'd', range=(1, 99), distinct=True), [2, 4], None),
    (Parameter('gate', 20.0, 'd', range=(0.1, 1000.0)), 25, None),            # an int where a float goes
    (Parameter('gate', 20.0, 'd', range=(0.1, 1000.0)), 0.0, 'in [0.1, 1000.0]'),
    (Parameter('gate', 20.0, 'd', range=(0.1, 1000.0)), 'far', 'must be a float'),
    (Parameter('count', 150, 'd', range=(1, 10)), 2.0, 'must be a int'),
    (Parameter('method', 'regions', 'd', choices=('regions', 'nearest')), 'best', 'one of regions, nearest'),
])
def test_checks(parameter, value, problem):
    found = check(parameter, value)
    assert found is None if problem is None else problem in found and parameter.name in found


def test_a_bad_params_file_names_the_file_and_the_parameter(tmp_path):
    path = tmp_path / 'fitter.yaml'
    path.write_text('/**: {ros__parameters: {outline_gate: -1.0}}')
    with pytest.raises(ParameterError, match=r'fitter\.yaml: .*outline_gate'):
        load_parameters(path, SKELETON_FITTER, 'skeleton_fitter')


def call(node, client, request):
    assert client.wait_for_service(timeout_sec=20), f'no service {client.srv_name}'
    future = client.call_async(request)
    rclpy.spin_until_future_complete(node, future, timeout_sec=20)
    assert future.done(), f'{client.srv_name} did not answer'
    return future.result()


def test_skeleton_fitter_exposes_its_settings_as_described_read_only_parameters(background, ros_context):
    fitter = background('run', 'skeleton_fitter', '--ros-args', '-p', 'outline_gate:=25.0', '-p', 'cameras:=[2, 4]')
    node = rclpy.create_node('parameter_reader')
    try:
        names = ['outline_gate', 'cameras', 'upright_tilt_deg']
        described = call(node, node.create_client(DescribeParameters, '/skeleton_fitter/describe_parameters'),
                         DescribeParameters.Request(names=names)).descriptors
        values = call(node, node.create_client(GetParameters, '/skeleton_fitter/get_parameters'),
                      GetParameters.Request(names=names)).values
    finally:
        node.destroy_node()
    gate, cameras, tilt = described
    assert '[px]' in gate.description and gate.read_only
    assert (gate.floating_point_range[0].from_value, gate.floating_point_range[0].to_value) == (0.1, 1000.0)
    assert '[deg]' in tilt.description
    assert 'each in [1, 99], all different' in cameras.additional_constraints
    assert values[0].type == ParameterType.PARAMETER_DOUBLE and math.isclose(values[0].double_value, 25.0)
    assert list(values[1].integer_array_value) == [2, 4]
    code, _, err = fitter.interrupt()
    assert code == 0, err


@pytest.mark.parametrize('executable, arguments, fragment', [
    ('skeleton_fitter', ['-p', 'cameras:=[3, 3]'], "'cameras' must list distinct values"),
    ('marker_skeleton', ['-p', 'cameras:=[0]'], "'cameras' must have every value in [1, 99]"),
    ('marker_tracker', ['-r', '__ns:=/cam3', '-p', 'method:=best'], "'method' must be one of regions, nearest"),
])
def test_a_bad_value_stops_the_node_with_one_line(executable, arguments, fragment):
    result = run_mvpose('run', executable, '--ros-args', *arguments, check=False, timeout=60)
    assert_one_line_error(result, fragment)
    assert result.returncode == 2
