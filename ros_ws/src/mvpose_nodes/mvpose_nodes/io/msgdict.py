"""ROS 2 messages to and from plain Python data, YAML and CSV, as ros2cli prints and parses them.

rosidl_runtime_py (what `ros2 topic echo` and `ros2 topic pub` use) is not among the PyPI
wheels this project runs on, so this module provides the same conversions. It works on
message instances and classes only and never touches rclpy.

The output matches rosidl_runtime_py's (`message_to_yaml` prints what `ros2 topic echo`
prints). Setting fields is stricter than `ros2 topic pub`: a value of the wrong kind (a
string for a number, a float for an integer) is an error instead of being cast with
`int()`/`float()`/`str()`, and every error is a one-line `FieldError` naming the field path
and the message type.
"""
import array
import importlib
import math
import sys

import numpy
import yaml
from rosidl_parser.definition import (AbstractGenericString, AbstractNestedType, AbstractString,
                                      AbstractWString, Array, BasicType, BoundedSequence,
                                      NamespacedType)

FLOAT_TYPES = {'float', 'double', 'long double'}  # rosidl BasicType.typename values
# The exact float32 maximum; the generated setters' check uses the rounded 3.402823466e+38,
# which would refuse a float32 array's own largest element read back from YAML.
FLOAT32_MAX = float(numpy.finfo(numpy.float32).max)
# Inclusive value range of each integer type; rosidl's Python 'char' is an unsigned byte.
INTEGER_RANGES = {'char': (0, 2**8 - 1),
                  **{f'int{bits}': (-2**(bits - 1), 2**(bits - 1) - 1) for bits in (8, 16, 32, 64)},
                  **{f'uint{bits}': (0, 2**bits - 1) for bits in (8, 16, 32, 64)}}


class FieldError(ValueError):
    """A field path or value does not fit the message type; the message is one line."""


def message_type_name(msg_or_class):
    """'pkg/msg/Type' of a message instance or class, e.g. 'mvpose_msgs/msg/Skeleton'."""
    cls = msg_or_class if isinstance(msg_or_class, type) else type(msg_or_class)
    package, interface_kind = cls.__module__.split('.')[:2]  # e.g. mvpose_msgs.msg._skeleton
    return f'{package}/{interface_kind}/{cls.__name__}'


def _field_types(msg):
    """Field name -> rosidl_parser type, in declaration order."""
    return dict(zip(msg.get_fields_and_field_types(), msg.SLOT_TYPES))


def _type_name(value_type):
    """The element type name rosidl_runtime_py prints in abbreviated sequences."""
    if isinstance(value_type, BasicType):
        return value_type.typename
    if isinstance(value_type, AbstractWString):
        return 'wstring'
    if isinstance(value_type, AbstractString):
        return 'string'
    if isinstance(value_type, NamespacedType):
        return '/'.join(value_type.namespaced_name())
    return 'unknown'


def _abbreviate_sequence(value, field_type):
    """The `no_arr` placeholder of a sequence or array field, in rosidl_runtime_py's wording."""
    element = _type_name(field_type.value_type)
    if isinstance(field_type, Array):
        return f'<array type: {element}[{field_type.size}]>'
    if isinstance(field_type, BoundedSequence):
        return f'<sequence type: {element}[{field_type.maximum_size}], length: {len(value)}>'
    return f'<sequence type: {element}, length: {len(value)}>'


def message_to_ordereddict(msg, truncate_length=None, no_arr=False, no_str=False):
    """The message as a dict in field order: nested messages as dicts, sequences as lists.

    truncate_length: strings longer than this keep that many characters plus '...';
    sequences longer than this keep that many items followed by the item '...'.
    no_arr: every sequence or array field becomes a string, '<sequence type: T, length: N>'
    or '<array type: T[n]>'.
    no_str: every string becomes '<string length: <N>>'.
    """
    options = dict(truncate_length=truncate_length, no_arr=no_arr, no_str=no_str)
    return {name: _plain_value(getattr(msg, name), field_type, **options)
            for name, field_type in _field_types(msg).items()}


def _plain_value(value, field_type, truncate_length, no_arr, no_str):
    """One field value (or sequence element, field_type None) as plain Python data."""
    options = dict(truncate_length=truncate_length, no_arr=no_arr, no_str=no_str)
    if isinstance(value, bytes):  # byte/octet fields: one character per byte, like ros2cli
        value = ''.join(map(chr, value))
        if truncate_length is not None and len(value) > truncate_length:
            value = value[:truncate_length] + '...'
        return value
    if isinstance(value, str):
        if no_str:
            return f'<string length: <{len(value)}>>'
        if truncate_length is not None and len(value) > truncate_length:
            return value[:truncate_length] + '...'
        return value
    if isinstance(value, (list, tuple, array.array, numpy.ndarray)):
        # Elements pass field_type None: no_arr abbreviates fields, not the items inside them.
        if no_arr and field_type is not None:
            return _abbreviate_sequence(value, field_type)
        items = [_plain_value(item, None, **options) for item in value[:truncate_length]]
        if truncate_length is not None and len(value) > truncate_length:
            items.append('...')
        return items
    if isinstance(value, numpy.generic):  # elements of fixed-size arrays
        return value.item()
    if isinstance(value, (bool, int, float)):
        return value
    return message_to_ordereddict(value, **options)


class _YamlDumper(yaml.SafeDumper):
    """PyYAML's safe dumper, but strings holding U+0085 (NEL) are written double-quoted.

    PyYAML (allow_unicode) writes such a string single-quoted, where the reader takes NEL
    for a line break, so it would not load back; ros2cli has that flaw, we need not.
    """

    def represent_str(self, text):
        style = '"' if '\x85' in text else None
        return self.represent_scalar('tag:yaml.org,2002:str', text, style=style)


_YamlDumper.add_representer(str, _YamlDumper.represent_str)


def message_to_yaml(msg, truncate_length=None, no_arr=False, no_str=False, flow_style=False):
    """The YAML text `ros2 topic echo` prints for one message (without the '---' separator)."""
    fields = message_to_ordereddict(msg, truncate_length=truncate_length, no_arr=no_arr,
                                    no_str=no_str)
    # width=sys.maxsize: ros2cli never wraps long strings or flow-style lines.
    return yaml.dump(fields, Dumper=_YamlDumper, default_flow_style=flow_style, sort_keys=False,
                     allow_unicode=True, width=sys.maxsize)


def message_to_csv(msg, truncate_length=None, no_arr=False, no_str=False):
    """`ros2 topic echo --csv`: every leaf value depth-first in field order, joined by ','."""
    fields = message_to_ordereddict(msg, truncate_length=truncate_length, no_arr=no_arr,
                                    no_str=no_str)
    return ','.join(_csv_leaves(fields))


def _csv_leaves(value):
    """The CSV cells of a plain value. An empty sequence is one empty cell, as in ros2cli."""
    if isinstance(value, dict):
        for item in value.values():
            yield from _csv_leaves(item)
    elif isinstance(value, list):
        if not value:
            yield ''
        for item in value:
            yield from _csv_leaves(item)
    else:
        yield str(value)


def get_message_field(msg, path):
    """The value at a dotted path such as 'header.stamp.sec' or 'joints.3.position.x'.

    A component that is an integer indexes a sequence (negative counts from the end).
    Values are returned as stored: messages, array.array, numpy arrays; numpy scalars
    (elements of fixed-size arrays) as Python numbers.
    Raises FieldError naming the path and the message type for an unknown field or index.
    """
    value = msg
    walked = []  # the components resolved so far, for the error message
    for component in path.split('.'):
        where = '.'.join(walked) or 'the message'
        if isinstance(value, (list, tuple, array.array, numpy.ndarray)):
            try:
                value = value[int(component)]
            except ValueError:
                raise FieldError(f"{path}: {where} is a sequence, {component!r} is not an index "
                                 f"(in {message_type_name(msg)})") from None
            except IndexError:
                raise FieldError(f'{path}: index {component} out of range for {where} '
                                 f'(length {len(value)}) in {message_type_name(msg)}') from None
        elif hasattr(value, 'get_fields_and_field_types'):
            fields = value.get_fields_and_field_types()
            if component not in fields:
                raise FieldError(f'{path}: no field {component!r} in {message_type_name(value)} '
                                 f'(fields: {", ".join(fields)})')
            value = getattr(value, component)
        else:
            raise FieldError(f'{path}: {where} is {type(value).__name__} {value!r}, it has no '
                             f'field {component!r} (in {message_type_name(msg)})')
        walked.append(component)
    return value.item() if isinstance(value, numpy.generic) else value


def set_message_fields(msg, values):
    """Fill msg from nested dicts and lists as parsed from YAML (what `ros2 topic pub` takes).

    Fields not named in values keep their current value. Nested messages take dicts,
    sequences of messages take lists of dicts, number fields take numbers (an int is fine
    for a float field), byte fields take a one-character string or an int. Returns msg.
    Raises FieldError naming the field path and message type for an unknown field or a
    value that does not fit.
    """
    return _set_fields(msg, values, path='')


def _set_fields(msg, values, path):
    """Fill msg from the dict values and return it; path is msg's dotted path, for errors."""
    type_name = message_type_name(msg)
    if not isinstance(values, dict):
        raise FieldError(f'{path or "message"}: expected a mapping of fields for {type_name}, '
                         f'got {type(values).__name__} {values!r}')
    field_types = _field_types(msg)
    for name, value in values.items():
        field_path = f'{path}.{name}' if path else str(name)
        if name not in field_types:
            raise FieldError(f'{field_path}: no field {name!r} in {type_name} '
                             f'(fields: {", ".join(field_types)})')
        field_type = field_types[name]
        field = f'{type_name} field {name!r} ({msg.get_fields_and_field_types()[name]})'
        if isinstance(field_type, NamespacedType):
            # Fill the existing nested message so fields not given keep their values.
            _set_fields(getattr(msg, name), value, field_path)
            continue
        if isinstance(field_type, AbstractNestedType):
            _check_sequence_length(field_type, value, field_path, field)
            value = [_converted_element(field_type.value_type, item, f'{field_path}.{index}', field)
                     for index, item in enumerate(value)]
        else:
            value = _converted_element(field_type, value, field_path, field)
        # The generated setter turns lists into array.array / numpy arrays as the field needs.
        setattr(msg, name, value)
    return msg


def _check_sequence_length(field_type, value, path, field):
    """Raise FieldError unless value is a list whose length field_type allows.

    The generated setters check nothing unless ROS_PYTHON_CHECK_FIELDS=1, so the lengths,
    like the ranges in _converted_element, are checked here.
    """
    if not isinstance(value, (list, tuple)):
        raise FieldError(f'{path}: expected a list for {field}, got {type(value).__name__} {value!r}')
    if isinstance(field_type, Array) and len(value) != field_type.size:
        raise FieldError(f'{path}: expected exactly {field_type.size} items for {field}, '
                         f'got {len(value)}')
    if isinstance(field_type, BoundedSequence) and len(value) > field_type.maximum_size:
        raise FieldError(f'{path}: expected at most {field_type.maximum_size} items for {field}, '
                         f'got {len(value)}')


def _converted_element(value_type, value, path, field):
    """value as a field (or sequence element) of value_type holds it; field names it for errors."""
    if isinstance(value_type, NamespacedType):
        module = importlib.import_module('.'.join(value_type.namespaces))
        return _set_fields(getattr(module, value_type.name)(), value, path)
    # bool is an int subclass, but true for a number field is a mistake, not a 1.
    is_number = isinstance(value, (int, float)) and not isinstance(value, bool)
    if isinstance(value_type, AbstractGenericString):
        maximum = getattr(value_type, 'maximum_size', None)  # only bounded strings have one
        if maximum is None:
            fits, expected = isinstance(value, str), 'a string'
        else:
            fits, expected = isinstance(value, str) and len(value) <= maximum, \
                f'a string of at most {maximum} characters'
    elif value_type.typename == 'boolean':
        fits, expected = isinstance(value, bool), 'a boolean (true/false)'
    elif value_type.typename in FLOAT_TYPES:
        # float32, as the generated setter's check: finite values within range, or inf.
        fits = is_number and (value_type.typename != 'float' or abs(value) <= FLOAT32_MAX
                              or math.isinf(value))
        expected = 'a number' if value_type.typename != 'float' else 'a number within float32 range'
        value = float(value) if fits else value  # an int from YAML for a float field
    elif value_type.typename in INTEGER_RANGES:
        low, high = INTEGER_RANGES[value_type.typename]
        fits = is_number and isinstance(value, int) and low <= value <= high
        expected = f'an integer in [{low}, {high}]'
    else:  # byte/octet: ros2cli prints one character per byte; an int 0..255 is accepted too
        expected = 'one byte (a 1-character string or an integer in [0, 255])'
        if isinstance(value, str) and len(value) == 1 and ord(value) < 256:
            value = value.encode('latin-1')
        elif is_number and isinstance(value, int) and 0 <= value < 256:
            value = bytes([value])
        fits = isinstance(value, bytes) and len(value) == 1
    if not fits:
        raise FieldError(f'{path}: expected {expected} for {field}, '
                         f'got {type(value).__name__} {value!r}')
    return value
