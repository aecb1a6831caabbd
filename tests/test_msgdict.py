"""mvpose_nodes.io.msgdict: messages to dict / YAML / CSV as `ros2 topic echo` prints them, and back."""
import importlib
import random

import pytest
import yaml
from builtin_interfaces.msg import Time
from geometry_msgs.msg import Point, Pose, Quaternion
from rosidl_parser.definition import (AbstractGenericString, AbstractNestedType, Array,
                                      BoundedSequence, NamespacedType)
from sensor_msgs.msg import CameraInfo, Image
from std_msgs.msg import ByteMultiArray, Header
from visualization_msgs.msg import MarkerArray

from mvpose_msgs.msg import FitStage, LabelledContour, Skeleton, SkinEllipseArray
from mvpose_nodes.io.msgdict import (FieldError, get_message_field, message_to_csv,
                                  message_to_ordereddict, message_to_yaml, message_type_name,
                                  set_message_fields)

pytestmark = pytest.mark.cli


def header(sec=1, nanosec=2, frame_id='world'):
    return Header(stamp=Time(sec=sec, nanosec=nanosec), frame_id=frame_id)


def pose(x, y, z, qw=1.0):
    return Pose(position=Point(x=x, y=y, z=z), orientation=Quaternion(w=qw))


def small_skeleton():
    return Skeleton(header=header(), joint_names=['pelvis', 'neck'],
                    joints=[pose(0.0, 0.0, 1.0), pose(0.5, -0.25, 1.5, qw=0.5)],
                    parameters=[1.0, 2.5], stages=[FitStage(name='torso', cost=3.5, evaluations=7,
                                                            cameras=[1, 5], fitted=True)],
                    status=Skeleton.STATUS_DEGRADED, status_message='cam 3 missing', fit_time=0.125)


SKELETON_YAML = """\
header:
  stamp:
    sec: 1
    nanosec: 2
  frame_id: world
joint_names:
- pelvis
- neck
joints:
- position:
    x: 0.0
    y: 0.0
    z: 1.0
  orientation:
    x: 0.0
    y: 0.0
    z: 0.0
    w: 1.0
- position:
    x: 0.5
    y: -0.25
    z: 1.5
  orientation:
    x: 0.0
    y: 0.0
    z: 0.0
    w: 0.5
parameter_names: []
parameters:
- 1.0
- 2.5
stages:
- name: torso
  cost: 3.5
  evaluations: 7
  cameras:
  - 1
  - 5
  fitted: true
status: 2
status_message: cam 3 missing
fit_time: 0.125
"""


# --- message_to_yaml / message_to_ordereddict ------------------------------------------------

def test_header_yaml():
    assert message_to_yaml(header()) == 'stamp:\n  sec: 1\n  nanosec: 2\nframe_id: world\n'


def test_pose_yaml():
    assert message_to_yaml(pose(1.0, 2.0, -3.5)) == (
        'position:\n  x: 1.0\n  y: 2.0\n  z: -3.5\n'
        'orientation:\n  x: 0.0\n  y: 0.0\n  z: 0.0\n  w: 1.0\n')


def test_skeleton_yaml_keeps_field_order_and_nests_sequences_of_messages():
    assert message_to_yaml(small_skeleton()) == SKELETON_YAML


def test_ordereddict_is_plain_python_data_in_field_order():
    fields = message_to_ordereddict(small_skeleton())
    assert list(fields) == list(Skeleton.get_fields_and_field_types())
    assert fields['parameters'] == [1.0, 2.5] and type(fields['parameters']) is list
    assert type(fields['stages'][0]['cameras'][0]) is int
    assert fields['joints'][1]['position'] == {'x': 0.5, 'y': -0.25, 'z': 1.5}


def test_camera_info_fixed_arrays_and_sequence():
    info = CameraInfo(header=header(frame_id='cam1_optical_frame'), height=480, width=640,
                      distortion_model='plumb_bob', d=[-0.25, 0.125, 0.0, 0.0, 1e-05],
                      k=[500, 0, 320.5, 0, 500, 240.5, 0, 0, 1],
                      r=[1, 0, 0, 0, 1, 0, 0, 0, 1],
                      p=[500, 0, 320.5, 0, 0, 500, 240.5, 0, 0, 0, 1, 0])
    flat = message_to_ordereddict(info)
    assert all(type(value) is float for key in 'dkrp' for value in flat[key])  # not numpy.float64
    assert message_to_yaml(info) == """\
header:
  stamp:
    sec: 1
    nanosec: 2
  frame_id: cam1_optical_frame
height: 480
width: 640
distortion_model: plumb_bob
d:
- -0.25
- 0.125
- 0.0
- 0.0
- 1.0e-05
k:
- 500.0
- 0.0
- 320.5
- 0.0
- 500.0
- 240.5
- 0.0
- 0.0
- 1.0
r:
- 1.0
- 0.0
- 0.0
- 0.0
- 1.0
- 0.0
- 0.0
- 0.0
- 1.0
p:
- 500.0
- 0.0
- 320.5
- 0.0
- 0.0
- 500.0
- 240.5
- 0.0
- 0.0
- 0.0
- 1.0
- 0.0
binning_x: 0
binning_y: 0
roi:
  x_offset: 0
  y_offset: 0
  height: 0
  width: 0
  do_rectify: false
"""


def test_uint8_sequence_is_a_list_of_ints_and_empty_sequences_are_flow_lists():
    contour = LabelledContour(header=header(), x=[10, 11], y=[20, 21],
                              labels=[LabelledContour.LABEL_TORSO, LabelledContour.LABEL_HEAD],
                              sides=[LabelledContour.SIDE_A, LabelledContour.SIDE_B])
    assert message_to_yaml(contour) == """\
header:
  stamp:
    sec: 1
    nanosec: 2
  frame_id: world
status: 0
status_message: ''
x:
- 10
- 11
y:
- 20
- 21
labels:
- 1
- 2
sides:
- 1
- 2
keypoints: []
"""


def test_yaml_quotes_strings_that_would_read_back_as_other_types_and_keeps_unicode():
    text = message_to_yaml(Header(frame_id='yes'))
    assert text.endswith("frame_id: 'yes'\n")
    assert message_to_yaml(Header(frame_id='naïve ✓')).endswith('frame_id: naïve ✓\n')


def test_yaml_does_not_wrap_long_strings():
    long_name = ' '.join(['word'] * 100)
    assert message_to_yaml(Header(frame_id=long_name)).endswith(f'frame_id: {long_name}\n')


def test_flow_style():
    assert message_to_yaml(header(), flow_style=True) == (
        '{stamp: {sec: 1, nanosec: 2}, frame_id: world}\n')


def test_truncate_length_cuts_strings_and_sequences_at_every_depth():
    fields = message_to_ordereddict(small_skeleton(), truncate_length=3)
    assert fields['header']['frame_id'] == 'wor...'
    assert fields['joint_names'] == ['pel...', 'nec...']
    assert fields['parameters'] == [1.0, 2.5]  # not longer than 3: unchanged
    assert fields['status_message'] == 'cam...'
    fields = message_to_ordereddict(small_skeleton(), truncate_length=1)
    assert fields['joints'] == [message_to_ordereddict(pose(0.0, 0.0, 1.0)), '...']
    assert fields['stages'][0]['cameras'] == [1, '...']
    assert message_to_yaml(Header(frame_id='world'), truncate_length=2).endswith(
        "frame_id: wo...\n")


def test_no_arr_abbreviates_sequences_and_arrays():
    fields = message_to_ordereddict(small_skeleton(), no_arr=True)
    assert fields['joint_names'] == '<sequence type: string, length: 2>'
    assert fields['joints'] == '<sequence type: geometry_msgs/msg/Pose, length: 2>'
    assert fields['parameter_names'] == '<sequence type: string, length: 0>'
    assert fields['parameters'] == '<sequence type: double, length: 2>'
    assert fields['stages'] == '<sequence type: mvpose_msgs/msg/FitStage, length: 1>'
    assert fields['header'] == message_to_ordereddict(header())  # not a sequence: unchanged
    camera = message_to_ordereddict(CameraInfo(d=[0.5]), no_arr=True)
    assert (camera['d'], camera['k'], camera['p']) == (
        '<sequence type: double, length: 1>', '<array type: double[9]>', '<array type: double[12]>')
    assert "labels: '<sequence type: uint8, length: 0>'\n" in message_to_yaml(
        LabelledContour(), no_arr=True)


def test_no_str_replaces_strings_with_their_length():
    fields = message_to_ordereddict(small_skeleton(), no_str=True)
    assert fields['header']['frame_id'] == '<string length: <5>>'
    assert fields['joint_names'] == ['<string length: <6>>', '<string length: <4>>']
    assert fields['stages'][0]['name'] == '<string length: <5>>'
    assert fields['status_message'] == '<string length: <13>>'


def test_byte_fields_print_one_character_per_byte_and_load_back():
    message = ByteMultiArray(data=[b'a', b'\x01', b'\x85', b'\xff'])
    assert message_to_ordereddict(message)['data'] == ['a', '\x01', '\x85', '\xff']
    assert set_message_fields(ByteMultiArray(), yaml.safe_load(message_to_yaml(message))) == message


# --- message_to_csv ---------------------------------------------------------------------------

def test_pose_csv():
    assert message_to_csv(pose(1.0, 2.0, 3.0, qw=0.5)) == '1.0,2.0,3.0,0.0,0.0,0.0,0.5'


def test_csv_expands_sequences_depth_first_and_empty_sequences_are_empty_cells():
    assert message_to_csv(small_skeleton()) == (
        '1,2,world,pelvis,neck,0.0,0.0,1.0,0.0,0.0,0.0,1.0,0.5,-0.25,1.5,0.0,0.0,0.0,0.5,'
        ',1.0,2.5,torso,3.5,7,1,5,True,2,cam 3 missing,0.125')


def test_csv_options():
    assert message_to_csv(small_skeleton(), truncate_length=1, no_str=True).startswith(
        '1,2,<string length: <5>>,<string length: <6>>,...,0.0,')
    assert message_to_csv(CameraInfo(d=[1.0]), no_arr=True) == (
        '0,0,,0,0,,<sequence type: double, length: 1>,<array type: double[9]>,'
        '<array type: double[9]>,<array type: double[12]>,0,0,0,0,0,0,False')


# --- get_message_field ------------------------------------------------------------------------

def test_get_message_field_walks_nested_fields_and_indexes():
    skeleton = small_skeleton()
    assert get_message_field(skeleton, 'header.stamp.sec') == 1
    assert get_message_field(skeleton, 'header.frame_id') == 'world'
    assert get_message_field(skeleton, 'joints.1.position.y') == -0.25
    assert get_message_field(skeleton, 'joints.-1.orientation.w') == 0.5
    assert get_message_field(skeleton, 'joint_names.1') == 'neck'
    assert get_message_field(skeleton, 'stages.0.cameras.1') == 5
    assert get_message_field(skeleton, 'joints.0') == pose(0.0, 0.0, 1.0)
    element = get_message_field(CameraInfo(k=list(range(9))), 'k.2')
    assert element == 2.0 and type(element) is float


@pytest.mark.parametrize('path, message_words', [
    ('foo', ["foo: no field 'foo' in mvpose_msgs/msg/Skeleton (fields: header, joint_names,"]),
    ('header.stamp.foo', ["no field 'foo' in builtin_interfaces/msg/Time (fields: sec, nanosec)"]),
    ('joints.2.position', ['joints.2.position: index 2 out of range for joints (length 2)',
                           'mvpose_msgs/msg/Skeleton']),
    ('joints.x', ["joints is a sequence, 'x' is not an index", 'mvpose_msgs/msg/Skeleton']),
    ('status.value', ["status is int 2, it has no field 'value'", 'mvpose_msgs/msg/Skeleton']),
])
def test_get_message_field_errors_name_the_path_and_type(path, message_words):
    with pytest.raises(FieldError) as raised:
        get_message_field(small_skeleton(), path)
    assert '\n' not in str(raised.value)
    for words in message_words:
        assert words in str(raised.value)


def test_field_error_is_a_value_error():
    assert issubclass(FieldError, ValueError)


# --- set_message_fields -----------------------------------------------------------------------

def test_set_message_fields_round_trips_nested_messages_and_sequences_of_messages():
    values = {
        'header': {'stamp': {'sec': 5, 'nanosec': 6}, 'frame_id': 'world'},
        'joint_names': ['pelvis', 'left_hip'],
        'joints': [{'position': {'x': 0.0, 'y': 0.1, 'z': 0.9},
                    'orientation': {'x': 0.0, 'y': 0.0, 'z': 0.0, 'w': 1.0}},
                   {'position': {'x': 0.1, 'y': 0.1, 'z': 0.9},
                    'orientation': {'x': 0.5, 'y': 0.5, 'z': 0.5, 'w': 0.5}}],
        'parameter_names': ['tx'],
        'parameters': [0.25],
        'stages': [{'name': 'torso', 'cost': 1.5, 'evaluations': 40, 'cameras': [1, 2],
                    'fitted': True},
                   {'name': 'head_neck', 'cost': 0.0, 'evaluations': 0, 'cameras': [],
                    'fitted': False}],
        'status': 1,
        'status_message': 'initialising',
        'fit_time': 0.5,
    }
    skeleton = set_message_fields(Skeleton(), values)
    assert isinstance(skeleton, Skeleton)
    assert isinstance(skeleton.stages[1], FitStage)
    assert message_to_ordereddict(skeleton) == values


def test_set_message_fields_keeps_fields_not_given_and_converts_ints_for_float_fields():
    skeleton = small_skeleton()
    set_message_fields(skeleton, {'header': {'frame_id': 'map'}, 'fit_time': 2,
                                  'parameters': [1, 2]})
    assert skeleton.header.stamp.sec == 1 and skeleton.header.frame_id == 'map'
    assert skeleton.fit_time == 2.0 and type(skeleton.fit_time) is float
    assert list(skeleton.parameters) == [1.0, 2.0]
    assert skeleton.joint_names == ['pelvis', 'neck']


def test_set_message_fields_from_ros2_topic_pub_style_yaml():
    skeleton = set_message_fields(
        Skeleton(), yaml.safe_load('{header: {frame_id: world}, joint_names: [a, b]}'))
    assert skeleton.header.frame_id == 'world' and skeleton.joint_names == ['a', 'b']


def test_set_message_fields_fills_fixed_arrays():
    info = set_message_fields(CameraInfo(), {'k': [1, 0, 2, 0, 1, 3, 0, 0, 1], 'd': [0.5]})
    assert info.k.tolist() == [1.0, 0.0, 2.0, 0.0, 1.0, 3.0, 0.0, 0.0, 1.0]
    assert list(info.d) == [0.5]


@pytest.mark.parametrize('message, values, message_words', [
    (Skeleton(), {'foo': 1},
     ["foo: no field 'foo' in mvpose_msgs/msg/Skeleton (fields: header, joint_names,"]),
    (Skeleton(), {'stages': [{'name': 'torso', 'costs': 1.0}]},
     ["stages.0.costs: no field 'costs' in mvpose_msgs/msg/FitStage"]),
    (Skeleton(), {'fit_time': '1.5'},
     ["fit_time: expected a number for mvpose_msgs/msg/Skeleton field 'fit_time' (double), "
      "got str '1.5'"]),
    (Skeleton(), {'stages': [{'cost': 'high'}]},
     ["stages.0.cost: expected a number", 'mvpose_msgs/msg/FitStage']),
    (Skeleton(), {'parameters': [1.0, 'x']}, ['parameters.1: expected a number']),
    (Skeleton(), {'status': 1.5}, ['status: expected an integer in [0, 255]', '(uint8)']),
    (Skeleton(), {'status': 256}, ['status: expected an integer in [0, 255]']),
    (Skeleton(), {'status': True}, ['status: expected an integer', 'got bool True']),
    (Skeleton(), {'joint_names': [1]}, ['joint_names.0: expected a string']),
    (Skeleton(), {'joint_names': 'pelvis'}, ['joint_names: expected a list']),
    (Skeleton(), {'header': 'auto'}, ['header: expected a mapping of fields for std_msgs/msg/Header']),
    (Skeleton(), {'stages': [{'cameras': [-1]}]}, ['stages.0.cameras.0: expected an integer']),
    (CameraInfo(), {'k': [1.0, 2.0]}, ['k: expected exactly 9 items', 'sensor_msgs/msg/CameraInfo']),
    (CameraInfo(), {'k': ['1'] * 9}, ['k.0: expected a number']),
])
def test_set_message_fields_errors_name_the_field_and_type(message, values, message_words):
    with pytest.raises(FieldError) as raised:
        set_message_fields(message, values)
    assert '\n' not in str(raised.value)
    for words in message_words:
        assert words in str(raised.value)


def test_message_type_name():
    assert message_type_name(Skeleton) == 'mvpose_msgs/msg/Skeleton'
    assert message_type_name(small_skeleton()) == 'mvpose_msgs/msg/Skeleton'
    assert message_type_name(CameraInfo()) == 'sensor_msgs/msg/CameraInfo'


# --- property: message_to_yaml -> yaml.safe_load -> set_message_fields gives the message back --

TRICKY_STRINGS = ['', 'yes', 'no', 'null', '~', '1.5', '0x1F', '007', 'a: b', '- x', '#hash',
                  "it's", '"quoted"', ' lead', 'trail ', 'multi\nline', 'tab\there', 'naïve ✓',
                  'nel\x85end', '[1, 2]', '{a: 1}', '&anchor', '*alias', '!tag', '%', '@', '`']
INTEGER_RANGES = {'char': (0, 255), 'octet': (0, 255), 'int8': (-2**7, 2**7 - 1),
                  'uint8': (0, 2**8 - 1), 'int16': (-2**15, 2**15 - 1), 'uint16': (0, 2**16 - 1),
                  'int32': (-2**31, 2**31 - 1), 'uint32': (0, 2**32 - 1),
                  'int64': (-2**63, 2**63 - 1), 'uint64': (0, 2**64 - 1)}


def random_value(value_type, rng):
    """A random value for one field or sequence element of the rosidl type value_type."""
    if isinstance(value_type, NamespacedType):
        cls = getattr(importlib.import_module('.'.join(value_type.namespaces)), value_type.name)
        return random_message(cls, rng)
    if isinstance(value_type, AbstractNestedType):
        if isinstance(value_type, Array):
            length = value_type.size
        elif isinstance(value_type, BoundedSequence):
            length = rng.randint(0, value_type.maximum_size)
        else:
            length = rng.randint(0, 3)
        return [random_value(value_type.value_type, rng) for _ in range(length)]
    if isinstance(value_type, AbstractGenericString):
        text = rng.choice(TRICKY_STRINGS + [''.join(rng.choice('abcXYZ 09_:-/é') for _ in range(8))])
        return text[:getattr(value_type, 'maximum_size', None)]
    typename = value_type.typename
    if typename == 'boolean':
        return rng.random() < 0.5
    if typename == 'octet':
        return bytes([rng.randint(0, 255)])
    if typename in INTEGER_RANGES:
        low, high = INTEGER_RANGES[typename]
        return rng.choice([low, high, 0, rng.randint(low, high)])
    largest = 3.4028234663852886e38 if typename == 'float' else 1.7976931348623157e308
    return rng.choice([0.0, -1.0, 1e-300, largest, -largest, float('inf'), float('-inf'),
                       rng.uniform(-1e6, 1e6), rng.uniform(-1.0, 1.0)])


def random_message(cls, rng):
    message = cls()
    for name, value_type in zip(message.get_fields_and_field_types(), message.SLOT_TYPES):
        setattr(message, name, random_value(value_type, rng))
    return message


@pytest.mark.parametrize('cls', [Skeleton, LabelledContour, SkinEllipseArray, CameraInfo, Image,
                                 MarkerArray, ByteMultiArray, Header])
@pytest.mark.parametrize('seed', range(10))
def test_yaml_round_trip_of_random_messages(cls, seed):
    original = random_message(cls, random.Random(seed))
    text = message_to_yaml(original)
    copy = set_message_fields(cls(), yaml.safe_load(text))
    assert copy == original, text
    assert message_to_yaml(copy) == text


def test_round_trip_check_can_fail():
    """Guard for the property test: a changed field must make the copy differ."""
    original = random_message(Skeleton, random.Random(0))
    values = yaml.safe_load(message_to_yaml(original))
    values['fit_time'] = original.fit_time + 1.0 if abs(original.fit_time) < 1e300 else 0.5
    assert set_message_fields(Skeleton(), values) != original
