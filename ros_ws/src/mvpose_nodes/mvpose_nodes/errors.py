"""One place that turns user mistakes into one-line errors instead of tracebacks."""
import contextlib
import sys


class UserError(Exception):
    """Bad input from the user (file, topic, type, parameter): reported in one line, exit code 2."""


@contextlib.contextmanager
def exit_on_user_error(prog):
    """Print `prog: error: message` for a UserError and exit 2; exit 130 quietly on Ctrl-C."""
    try:
        yield
    except UserError as error:
        print(f'{prog}: error: {error}', file=sys.stderr)
        sys.exit(2)
    except KeyboardInterrupt:
        sys.exit(130)
