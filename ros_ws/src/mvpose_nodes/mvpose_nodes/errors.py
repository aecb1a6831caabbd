"""One place that turns user mistakes into one-line errors instead of tracebacks."""
import argparse
import contextlib
import sys


class UserError(Exception):
    """Bad input from the user (file, topic, type, parameter): reported in one line, exit code 2."""


class ArgumentParser(argparse.ArgumentParser):
    """argparse with a one-line error (`prog: error: ... (see --help)`) instead of usage + error."""

    def error(self, message):
        self.exit(2, f'{self.prog}: error: {message} (see {self.prog} --help)\n')


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
