"""Launch files in ros2 launch's YAML format: the subset that `./mvpose launch` reads (docs/launch.md).

The same file starts the same processes under `ros2 launch` on a system ROS 2 install:

  launch:
    - arg: {name: camera_a, default: '3', description: first camera}   # NAME:=VALUE on the command line
    - node:
        pkg: mvpose_nodes                 # required: the package of `exec`
        exec: camera_features             # required: PREFIX/lib/PKG/EXEC, as `ros2 run`
        name: camera_features             # required here: namespace/name is unique and prefixes the output
        namespace: /cam$(var camera_a)    # optional; a relative one is made absolute (/cam3)
        param:                            # optional, in this order on the command line:
          - from: $(find-pkg-share mvpose_nodes)/config/camera_features.yaml   # a params file
          - {name: cameras, value: [$(var camera_a), 5, 7]}   # a value: -p cameras:=[3, 5, 7]
        remap: [{from: image, to: image_raw}]   # optional
        args: --verbose                   # optional: a command line, placed before --ros-args
        output: screen                    # optional: screen or both; every output is printed anyway
        on_exit: shutdown                 # optional: when it ends (any code), stop all the others
        respawn: 'true'                   # optional, not with on_exit: run it again when it ends, after
        respawn_delay: '2.0'              # this many s (default 0), at most respawn_max_retries times (-1)
    - executable:
        name: player                      # required
        cmd: bag play bags/x              # a command line; its first word is a mvpose_nodes executable
        on_exit: shutdown                 # if one has that name, else a program on PATH (or a path)

Substitutions in string values: $(var NAME [DEFAULT]), $(env NAME [DEFAULT]), $(find-pkg-share PKG),
$(find-pkg-prefix PKG), $(exec-in-pkg EXEC PKG), $(dirname) (this file's folder). A param value that
holds a substitution is read as YAML once substituted ('3' -> 3), as launch_ros does; other strings stay
strings. Command lines (`cmd`, `args`) are split like a shell's; a substitution is never split. Relative
params-file paths resolve against the current directory, as under ros2 launch.

The whole file is checked before anything starts: any other key, action or substitution is a one-line
error naming the file, the place (launch[2].node, 0-based) and the key.
"""
import math
import os
import re
import shlex
import shutil
from dataclasses import dataclass
from pathlib import Path

import yaml
from ament_index_python.packages import PackageNotFoundError, get_package_prefix

from mvpose_nodes.tools.cli import UserError

DEFAULT_PACKAGE = 'mvpose_nodes'
RESPAWN_KEYS = ('respawn', 'respawn_delay', 'respawn_max_retries')
# The supported subset of each entity's keys (ros2 launch's names; docs/launch.md maps them).
ACTION_KEYS = {
    'arg': ('name', 'default', 'description'),
    'node': ('pkg', 'exec', 'name', 'namespace', 'param', 'remap', 'args', 'output', 'on_exit', *RESPAWN_KEYS),
    'executable': ('cmd', 'name', 'output', 'on_exit', *RESPAWN_KEYS),
}
PARAM_KEYS = ('from', 'name', 'value')
REMAP_KEYS = ('from', 'to')
OUTPUTS = ('screen', 'both')
# The supported substitutions, with the (fewest, most) arguments each takes.
SUBSTITUTION_ARGUMENTS = {'var': (1, 2), 'env': (1, 2), 'find-pkg-share': (1, 1), 'find-pkg-prefix': (1, 1),
                          'exec-in-pkg': (2, 2), 'dirname': (0, 0)}
IDENTIFIER = re.compile(r'[A-Za-z][A-Za-z0-9_-]*')
NAMESPACE = re.compile(r'/|(/[A-Za-z_][A-Za-z0-9_]*)+')
SCALARS = (bool, int, float, str)


@dataclass
class ProcessSpec:
    """A checked process: what to run, whether its end stops the launch, whether it is run again (respawn)."""
    name: str
    command: list
    required: bool = False
    respawn: bool = False
    respawn_delay: float = 0.0
    respawn_max_retries: int = -1


@dataclass
class Argument:
    """A launch argument (`arg`) as declared: name, default (unsubstituted; None if none), description."""
    name: str
    default: str = None
    description: str = ''


def package_prefix(package):
    """The install prefix of `package` (ament_index's), or None."""
    try:
        return Path(get_package_prefix(package))
    except PackageNotFoundError:
        return None


def package_executable(package, name):
    """Where `ros2 run PACKAGE NAME` finds NAME (PREFIX/lib/PACKAGE/NAME, PREFIX in AMENT_PREFIX_PATH), or None."""
    for prefix in filter(None, os.environ.get('AMENT_PREFIX_PATH', '').split(os.pathsep)):
        candidate = Path(prefix, 'lib', package, name)
        if candidate.is_file() and os.access(candidate, os.X_OK):
            return candidate
    return None


def package_launch_file(package, file_name):
    """The file called file_name in package's share directory, as `ros2 launch PACKAGE FILE` finds it."""
    prefix = package_prefix(package)
    if prefix is None:
        raise UserError(f"package '{package}' not found (not in AMENT_PREFIX_PATH)")
    share = prefix / 'share' / package
    found = sorted(path for path in share.rglob(file_name) if path.is_file())
    if len(found) != 1:
        problem = 'no file' if not found else f'{len(found)} files'
        raise UserError(f"{problem} named '{file_name}' in {share}")
    return found[0]


def yaml_value(value):
    """VALUE of `-p KEY:=VALUE`: compact YAML, which is how ROS reads it ([3, 5, 7], true, 'true')."""
    return yaml.safe_dump(value, default_flow_style=True, width=math.inf).strip().removesuffix('\n...')


def read_launch_file(path):
    """The `launch:` list of YAML file `path`; a one-line UserError if it is not a ros2 launch YAML file."""
    path = Path(path)
    try:
        document = yaml.safe_load(path.read_text())
    except FileNotFoundError:
        raise UserError(f'{path}: file not found') from None
    except OSError as error:
        raise UserError(f'{path}: cannot read: {error.strerror}') from None
    except yaml.YAMLError as error:
        mark = getattr(error, 'problem_mark', None)
        where = f' (line {mark.line + 1}: {error.problem})' if mark else ''
        raise UserError(f'{path}: not valid YAML{where}') from None
    if not isinstance(document, dict) or list(document) != ['launch']:
        raise UserError(f"{path}: expected ros2 launch's YAML format: a mapping with just a 'launch' list")
    if not isinstance(document['launch'], list):
        raise UserError(f"{path}: 'launch' must be a list of actions (arg, node, executable)")
    return document['launch']


def load_launch_file(path, arguments=None):
    """The checked process specs of launch file `path`, its args set from `arguments` ({name: value},
    as NAME:=VALUE on the command line) or their defaults; a one-line UserError for any mistake."""
    path = Path(path)
    return process_specs(read_launch_file(path), path.parent, source=str(path), arguments=arguments)


def declared_arguments(path):
    """The `arg`s that launch file `path` declares, in file order."""
    path = Path(path)
    return _declared(list(_entities(read_launch_file(path), str(path))), str(path))


def _declared(entities, source):
    arguments = []
    for kind, body, place in entities:
        if kind == 'arg':
            try:
                arguments.append(_argument(body))
            except UserError as error:
                raise UserError(f'{source}: {place}: {error}') from None
    return arguments


def process_specs(actions, base_dir='.', source='launch description', arguments=None):
    """Check a `launch:` list (actions as in a launch file) and build the command lines of its processes.

    base_dir: the launch file's folder, for $(dirname); arguments: {arg name: value} overriding defaults.
    Errors name `source` and the action's place (launch[K].node)."""
    arguments = {str(name): str(value) for name, value in (arguments or {}).items()}
    entities = list(_entities(actions, source))
    declared = [argument.name for argument in _declared(entities, source)]
    unknown = [name for name in arguments if name not in declared]
    if unknown:
        raise UserError(f"{source}: no launch argument '{unknown[0]}' (declared: {', '.join(declared) or 'none'})")
    variables, specs, arg_places, process_places = dict(arguments), [], {}, {}
    substitute = Substitutions(variables, Path(base_dir))
    for kind, body, place in entities:
        try:
            if kind == 'arg':
                argument = _argument(body)
                if argument.name in arg_places:
                    raise UserError(f"launch argument '{argument.name}' declared twice (also {arg_places[argument.name]})")
                arg_places[argument.name] = place
                if argument.name not in variables:
                    if argument.default is None:
                        raise UserError(f"launch argument '{argument.name}' has no default: "
                                        f'give it as {argument.name}:=VALUE')
                    variables[argument.name] = substitute(argument.default, 'default')
                continue
            spec = _node(body, substitute) if kind == 'node' else _executable(body, substitute)
            if spec.name in process_places:
                raise UserError(f"duplicate name '{spec.name}' (also {process_places[spec.name]})")
            process_places[spec.name] = place
        except UserError as error:
            raise UserError(f'{source}: {place}: {error}') from None
        specs.append(spec)
    if not specs:
        raise UserError(f'{source}: no node or executable to start')
    return specs


def _entities(actions, source):
    """(kind, body, place) of every action, each checked to be one known action with known keys."""
    if not isinstance(actions, list):
        raise UserError(f"{source}: 'launch' must be a list of actions (arg, node, executable)")
    for index, action in enumerate(actions):
        place = f'launch[{index}]'
        if not isinstance(action, dict) or len(action) != 1:
            raise UserError(f'{source}: {place}: must be a mapping with one key, the action '
                            f"({', '.join(ACTION_KEYS)})")
        (kind, body), = action.items()
        if kind not in ACTION_KEYS:
            raise UserError(f"{source}: {place}: unsupported action '{kind}' (supported: {', '.join(ACTION_KEYS)})")
        place = f'{place}.{kind}'
        if not isinstance(body, dict):
            raise UserError(f'{source}: {place}: must be a mapping of its keys ({", ".join(ACTION_KEYS[kind])})')
        try:
            _check_keys(body, ACTION_KEYS[kind])
        except UserError as error:
            raise UserError(f'{source}: {place}: {error}') from None
        yield kind, body, place


def _check_keys(mapping, supported):
    unknown = [str(key) for key in mapping if key not in supported]
    if unknown:
        raise UserError(f"unsupported key '{unknown[0]}' (supported: {', '.join(supported)})")


def _string(body, key, required=False):
    """body[key], which ros2 launch wants to be a string; None if absent and not required."""
    if key not in body:
        if required:
            raise UserError(f"needs '{key}'")
        return None
    value = body[key]
    if not isinstance(value, str):
        hint = f" (quote it: '{yaml_value(value)}')" if isinstance(value, (bool, int, float)) else ''
        raise UserError(f"'{key}' must be a string{hint}")
    return value


def _argument(body):
    name = _string(body, 'name', required=True)
    if not name:
        raise UserError("'name' is empty")
    return Argument(name, _string(body, 'default'), _string(body, 'description') or '')


def _node(body, substitute):
    package = substitute(_string(body, 'pkg', required=True), 'pkg')
    executable = substitute(_string(body, 'exec', required=True), 'exec')
    name = substitute(_string(body, 'name', required=True), 'name')
    if not name or '/' in name:
        raise UserError(f"'name' must be a node name, e.g. camera_features; got '{name}'")
    if '/' in executable:
        raise UserError("'exec' must be an executable's name, e.g. exec: camera_features")
    path = package_executable(package, executable)
    if path is None:
        raise UserError(f"no executable '{executable}' in package {package}")
    command = [str(path), *_command_line(body, 'args', substitute), '--ros-args', '-r', f'__node:={name}']
    namespace = _string(body, 'namespace')
    if namespace is not None:
        namespace = '/' + substitute(namespace, 'namespace').strip('/')
        if not NAMESPACE.fullmatch(namespace):
            raise UserError(f"'namespace' is not a ROS namespace: '{namespace}'")
        command += ['-r', f'__ns:={namespace}']
        name = f"{namespace.rstrip('/')}/{name}"  # the node's full name: unique where the plain name need not be
    command += _parameter_arguments(body.get('param', []), substitute)
    for index, remap in enumerate(_mappings(body.get('remap', []), 'remap', REMAP_KEYS)):
        try:
            original, replacement = (substitute(_string(remap, key, required=True), key) for key in REMAP_KEYS)
        except UserError as error:
            raise UserError(f'remap[{index}]: {error}') from None
        command += ['-r', f'{original}:={replacement}']
    return ProcessSpec(name, command, *_supervision(body, substitute))


def _executable(body, substitute):
    name = substitute(_string(body, 'name', required=True), 'name')
    if not name:
        raise UserError("'name' is empty")
    command = _command_line(body, 'cmd', substitute)
    if not command:
        raise UserError("'cmd' is empty")
    return ProcessSpec(name, [_program_path(command[0]), *command[1:]], *_supervision(body, substitute))


def _supervision(body, substitute):
    """(required, respawn, respawn_delay [s], respawn_max_retries (-1: no limit)), as ros2 launch reads them."""
    output, on_exit = _string(body, 'output'), _string(body, 'on_exit')
    if output is not None and substitute(output, 'output') not in OUTPUTS:
        raise UserError(f"'output' must be {' or '.join(OUTPUTS)} (every process's output is printed)")
    if on_exit is not None and on_exit != 'shutdown':
        raise UserError(f"'on_exit' must be shutdown, the only value ros2 launch takes; got '{on_exit}'")

    def value(key, default, valid, expected):
        raw = body.get(key, default)
        try:
            parsed = yaml.safe_load(substitute(raw, key)) if isinstance(raw, str) else raw
            if valid(parsed):
                return parsed
        except yaml.YAMLError:
            pass
        raise UserError(f"'{key}' must be {expected}; got '{raw}'")
    respawn = value('respawn', False, lambda v: isinstance(v, bool), 'true or false')
    delay = value('respawn_delay', 0.0, lambda v: type(v) in (int, float) and 0 <= v < math.inf, 'seconds >= 0')
    retries = value('respawn_max_retries', -1, lambda v: type(v) is int and v >= -1, 'a count, or -1 for no limit')
    if respawn and on_exit:
        raise UserError("'respawn' and 'on_exit: shutdown' exclude each other (restarted, or ending the launch)")
    return on_exit == 'shutdown', respawn, float(delay), retries


def _command_line(body, key, substitute):
    """The words of command line body[key], split as ros2 launch does: like a shell, each substitution's
    result joined to the text around it and never split itself."""
    text = _string(body, key, required=key == 'cmd')
    if text is None:
        return []
    words, pieces = [], []   # pieces: of the word being built

    def end_word():
        if pieces:
            words.append(''.join(pieces))
            pieces.clear()
    try:
        for fragment, substituted in substitute.fragments(text, key):
            if substituted:
                pieces.append(fragment)
                continue
            tokens = shlex.split(fragment)
            if not tokens or fragment[0].isspace():  # blanks end the word before
                end_word()
            if not tokens:
                continue
            pieces.append(tokens[0])
            if len(tokens) > 1:
                end_word()
                words.extend(tokens[1:-1])
                pieces.append(tokens[-1])
            if fragment[-1].isspace():
                end_word()
    except ValueError as error:  # shlex: an unclosed quote
        raise UserError(f"'{key}': cannot split the command line ({error})") from None
    end_word()
    return words


def _program_path(word):
    """The program a `cmd` starts with: a mvpose_nodes executable of that name, else one on PATH (or a path)."""
    found = ('/' not in word and package_executable(DEFAULT_PACKAGE, word)) or shutil.which(word)
    if not found:
        raise UserError(f"command not found: '{word}' (not an executable of {DEFAULT_PACKAGE}, not on PATH)")
    return str(found)


def _mappings(items, key, supported):
    if not isinstance(items, list) or not all(isinstance(item, dict) for item in items):
        raise UserError(f"'{key}' must be a list of mappings ({', '.join(supported)})")
    for index, item in enumerate(items):
        try:
            _check_keys(item, supported)
        except UserError as error:
            raise UserError(f'{key}[{index}]: {error}') from None
    return items


def _parameter_arguments(params, substitute):
    arguments = []
    for index, param in enumerate(_mappings(params, 'param', PARAM_KEYS)):
        try:
            if 'from' in param:
                if set(param) != {'from'}:
                    raise UserError("'from' (a params file) goes alone, without 'name' or 'value'")
                path = Path(os.path.abspath(substitute(_string(param, 'from'), 'from')))
                if not path.is_file():
                    raise UserError(f'parameters file not found: {path}')
                arguments += ['--params-file', str(path)]
            else:
                name = substitute(_string(param, 'name', required=True), 'name')
                if 'value' not in param:
                    raise UserError(f"parameter '{name}' needs a 'value' (or use 'from' for a params file)")
                arguments += ['-p', f"{name}:={yaml_value(_parameter_value(param['value'], substitute))}"]
        except UserError as error:
            raise UserError(f'param[{index}]: {error}') from None
    return arguments


def _parameter_value(value, substitute):
    """A param value as launch_ros evaluates it: a string with a substitution is read as YAML once
    substituted (so '$(var cameras)' with cameras:='[3, 5]' is a list); other scalars and strings are kept;
    a list's items must end up of one type."""
    def evaluated(item):
        if isinstance(item, str):
            fragments = substitute.fragments(item, 'value')
            if any(substituted for _, substituted in fragments):
                text = ''.join(fragment for fragment, _ in fragments)
                try:
                    return yaml.safe_load(text) if text else text
                except yaml.YAMLError:
                    raise UserError(f"value '{text}' is not valid YAML") from None
        return item
    value = evaluated(value) if not isinstance(value, list) else [evaluated(item) for item in value]
    items = value if isinstance(value, list) else [value]
    if not all(isinstance(item, SCALARS) for item in items):
        raise UserError(f"'value' must be a bool, number or string, or a list of them; got {value!r}")
    if not items:
        raise UserError("'value' is an empty list (ROS cannot tell its type)")
    if len({type(item) for item in items}) > 1:   # launch_ros refuses [1, 2.5] too: write [1.0, 2.5]
        raise UserError(f"a list value's items must all have one type (bool, int, float or str); got {items}")
    return value


class Substitutions:
    """Performs the $(...) substitutions of ros2 launch's frontend in a string; `variables` holds the launch
    arguments set so far (an `arg` is visible to the actions after it), base_dir is $(dirname)."""

    def __init__(self, variables, base_dir):
        self.variables = variables
        self.base_dir = base_dir

    def __call__(self, text, key):
        return ''.join(fragment for fragment, _ in self.fragments(text, key))

    def fragments(self, text, key):
        """[(text, substituted)]: the literal runs of `text` and the results of its substitutions, in order."""
        try:
            fragments, index, start = [], 0, 0
            while (index := text.find('$(', start)) >= 0:
                if index > start:
                    fragments.append((text[start:index], False))
                value, start = self._substitution(text, index)
                fragments.append((value, True))
            if start < len(text):
                fragments.append((text[start:], False))
            return fragments
        except UserError as error:
            raise UserError(f"'{key}': {error}") from None

    def _substitution(self, text, index):
        """(result, index after it) of the substitution that starts at text[index] ('$(')."""
        match = IDENTIFIER.match(text, index + 2)
        if not match:
            raise UserError(f"bad substitution in '{text}': expected $(NAME ARGUMENTS...)")
        name, index, arguments = match.group(), match.end(), []
        while index < len(text) and text[index] == ' ':
            argument, index = self._argument(text, index + 1)
            arguments.append(argument)
        if index >= len(text) or text[index] != ')':
            raise UserError(f"unclosed substitution in '{text}'")
        return self._perform(name, arguments), index + 1

    def _argument(self, text, index):
        """(value, index after it) of one argument of a substitution: plain, or quoted with ' or "."""
        quote = text[index] if index < len(text) and text[index] in '\'"' else None
        ends = quote or ' )'
        index += bool(quote)
        parts = []
        while index < len(text) and text[index] not in ends:
            if text.startswith('$(', index):
                value, index = self._substitution(text, index)
            else:
                value, index = text[index], index + 1
            parts.append(value)
        if quote:
            if index >= len(text):
                raise UserError(f"unclosed quote in '{text}'")
            index += 1
        return ''.join(parts), index

    def _perform(self, name, arguments):
        if name not in SUBSTITUTION_ARGUMENTS:
            raise UserError(f"unsupported substitution '$({name})' (supported: {', '.join(SUBSTITUTION_ARGUMENTS)})")
        low, high = SUBSTITUTION_ARGUMENTS[name]
        if not low <= len(arguments) <= high:
            wanted = str(low) if low == high else f'{low} or {high}'
            raise UserError(f'$({name}) takes {wanted} argument{"s" * (high != 1)}, got {len(arguments)}')
        if name == 'dirname':
            return os.path.abspath(self.base_dir)
        first, default = arguments[0], (arguments[1] if len(arguments) > 1 else None)
        if name in ('var', 'env'):
            values = self.variables if name == 'var' else os.environ
            if first in values:
                return values[first]
            if default is not None:
                return default
            if name == 'env':
                raise UserError(f'$(env {first}): environment variable {first} is not set')
            raise UserError(f"$(var {first}): no launch argument '{first}' declared before this point")
        if name == 'exec-in-pkg':
            path = package_executable(arguments[1], first)
            if path is None:
                raise UserError(f"$(exec-in-pkg {first} {arguments[1]}): no executable '{first}' in package "
                                f'{arguments[1]}')
            return str(path)
        prefix = package_prefix(first)
        if prefix is None:
            raise UserError(f"$({name} {first}): package '{first}' not found (not in AMENT_PREFIX_PATH)")
        return str(prefix / 'share' / first) if name == 'find-pkg-share' else str(prefix)
