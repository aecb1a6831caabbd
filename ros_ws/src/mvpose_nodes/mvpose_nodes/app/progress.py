"""A progress bar on stderr for long work: redrawn in place on a terminal, a line per tenth otherwise."""
import sys
import time


class Progress:
    def __init__(self, total, label, unit='frames', stream=sys.stderr):
        self.total, self.label, self.unit, self.stream = max(1, total), label, unit, stream
        self.done = 0
        self.started = time.monotonic()
        self.interactive = stream.isatty()
        self._last_tenth = -1

    def update(self, count=1):
        self.done += count
        elapsed = time.monotonic() - self.started
        remaining = elapsed / self.done * (self.total - self.done)
        filled = int(30 * self.done / self.total)
        text = (f'[{self.label}] {"█" * filled}{"░" * (30 - filled)} {self.done}/{self.total} {self.unit}'
                f'  {elapsed:5.1f} s  eta {remaining:4.0f} s')
        if self.interactive:
            print(f'\r{text}', end='', file=self.stream, flush=True)
        elif (tenth := 10 * self.done // self.total) != self._last_tenth:
            self._last_tenth = tenth
            print(text, file=self.stream, flush=True)

    def close(self):
        if self.interactive:
            print(file=self.stream, flush=True)
        return time.monotonic() - self.started
