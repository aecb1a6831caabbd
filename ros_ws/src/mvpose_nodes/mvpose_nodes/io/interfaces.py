"""Message types by name: the Python class, the .msg definition a bag stores, the type hash.

Names are ROS 2 type names, 'pkg/msg/Type' ('pkg/Type' is accepted too). Definitions
and hashes are read from the installed interface packages (share/<pkg>/msg/<Type>.msg
and .json under AMENT_PREFIX_PATH), the same files rosbag2 reads. No rclpy here.
"""
import functools
import importlib
import json
import os
import re
from pathlib import Path


class MessageTypeError(ValueError):
    """A message type name that is malformed or not installed; the message names the type."""


PRIMITIVE_TYPES = frozenset({
    'bool', 'byte', 'char', 'float32', 'float64', 'int8', 'uint8', 'int16', 'uint16',
    'int32', 'uint32', 'int64', 'uint64', 'string', 'wstring'})
# rosbag2 and the MCAP ros2msg profile separate a definition from each dependency this way.
DEPENDENCY_SEPARATOR = '=' * 80
TYPE_NAME = re.compile(r'^(?P<package>[A-Za-z][\w]*)/(?:(?P<kind>msg)/)?(?P<name>[A-Za-z]\w*)$')


def normalize_type_name(type_name):
    """'pkg/Type' or 'pkg/msg/Type' -> ('pkg', 'Type'); anything else is a MessageTypeError."""
    match = TYPE_NAME.match(type_name or '')
    if not match:
        raise MessageTypeError(f"'{type_name}' is not a message type name (expected e.g. mvpose_msgs/msg/Skeleton)")
    return match['package'], match['name']


def full_type_name(type_name):
    package, name = normalize_type_name(type_name)
    return f'{package}/msg/{name}'


def message_class(type_name):
    """The rosidl Python class of a message type, e.g. mvpose_msgs.msg.Skeleton."""
    package, name = normalize_type_name(type_name)
    try:
        module = importlib.import_module(f'{package}.msg')
    except ImportError:
        raise MessageTypeError(f"unknown message type '{type_name}': interface package '{package}' is not installed "
                        'in this environment') from None
    try:
        return getattr(module, name)
    except AttributeError:
        raise MessageTypeError(f"unknown message type '{type_name}': package '{package}' has no message '{name}'") from None


def _share_file(package, relative):
    for prefix in os.environ.get('AMENT_PREFIX_PATH', '').split(os.pathsep):
        candidate = Path(prefix, 'share', package, relative) if prefix else None
        if candidate is not None and candidate.is_file():
            return candidate
    raise MessageTypeError(f"no definition of '{package}/{relative}' under AMENT_PREFIX_PATH "
                    '(is the interface package installed and its setup sourced?)')


@functools.lru_cache(maxsize=None)
def message_definition(type_name):
    """The .msg text of one type, as installed."""
    package, name = normalize_type_name(type_name)
    return _share_file(package, f'msg/{name}.msg').read_text()


def field_types(definition, package):
    """The non-primitive field types a .msg text refers to, as 'pkg/msg/Type', in order."""
    found = []
    for line in definition.splitlines():
        words = line.split('#', 1)[0].split()
        if len(words) < 2 or '=' in words[1]:  # blank, comment, or a constant
            continue
        base = re.sub(r'\[.*\]$', '', words[0]).split('<=')[0]
        if base in PRIMITIVE_TYPES:
            continue
        dependency = base if '/' in base else f'{package}/{base}'
        found.append(full_type_name(dependency))
    return found


@functools.lru_cache(maxsize=None)
def schema_text(type_name):
    """The ros2msg schema of a type with every dependency appended, as rosbag2 stores it in MCAP."""
    root = full_type_name(type_name)
    ordered, pending = [], [root]
    while pending:
        current = pending.pop(0)
        if current in ordered:
            continue
        ordered.append(current)
        pending.extend(field_types(message_definition(current), current.split('/')[0]))
    parts = [message_definition(root).rstrip('\n') + '\n']
    for dependency in ordered[1:]:
        package, name = normalize_type_name(dependency)
        parts.append(f'{DEPENDENCY_SEPARATOR}\nMSG: {package}/{name}\n{message_definition(dependency).rstrip()}\n')
    return ''.join(parts)


@functools.lru_cache(maxsize=None)
def type_hash(type_name):
    """The RIHS01 type hash rosidl generated for a type ('' when the package ships none)."""
    package, name = normalize_type_name(type_name)
    try:
        description = json.loads(_share_file(package, f'msg/{name}.json').read_text())
    except MessageTypeError:
        return ''
    wanted = full_type_name(type_name)
    return next((entry['hash_string'] for entry in description.get('type_hashes', [])
                 if entry.get('type_name') == wanted), '')
