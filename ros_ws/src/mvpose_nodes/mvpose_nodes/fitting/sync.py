"""Approximate-time synchronisation of several message streams ("channels"), without ROS.

A port of ROS message_filters' ApproximateTime policy (wiki "message_filters/ApproximateTime", C++
`sync_policies/approximate_time.h`), pure Python so the skeleton fitter can use it and it can be tested without
rclpy. Guarantees, as in ROS:

* each message is used in at most one set;
* sets never cross: on every channel the messages of successive sets have strictly increasing stamps, so no set
  holds a message older than one of an earlier set, and set stamps strictly increase;
* each set has the smallest spread (newest − oldest stamp) among the sets that can follow the previous one
  contiguously (messages newer than the previous set's on every channel, the oldest of them on at least one);
  it is published only once no message still to come can give a narrower one (each channel is assumed to
  arrive in stamp order after the reorder window below);
* the output depends only on the stamps, not on the arrival order: messages are held until the newest stamp
  received is `reorder_window_ns` past theirs and then matched in stamp order, so any arrival order in which
  every message arrives within that window (and the queues do not overflow) gives the same sets;
* a set whose spread exceeds `max_interval_ns` is never published (its oldest message is dropped instead);
* a channel holds one message per stamp: a second one of the same stamp (a message sent twice) is dropped, so
  that it cannot make a set of its own after the first was used.

Beyond ROS: channels form groups (a camera's feature topics). A group whose newest stamp is more than
`timeout_ns` behind the input clock is silent; sets then form from the other groups ("degraded" sets, which
name the missing groups) until it is heard again. The input clock is the newest stamp matched, not wall time,
so a silent group is noticed only while others keep producing, and the result is deterministic in tests and
the same when replaying a bag at any speed. Also beyond ROS: `flush()` gives the sets still pending when the input
ends (a bag's last frame set, which would otherwise wait for a later message for ever), and a channel whose stamps
go back (`restart_ns`: a bag played again) starts the matching afresh instead of dropping the second play.

HeldSets keeps sets back until their cameras' calibration is in; PendingSets hands the newest sets to a
worker that is slower than the input (PendingSets: beyond its depth, the oldest are skipped and counted);
FrameRequests picks which announced frame set to ask the cameras for when the worker is ready, so that
frames are skipped before any camera computes their features, and by every camera alike.
"""
import bisect
import collections
import heapq
import itertools
import threading
from dataclasses import dataclass
from typing import NamedTuple


@dataclass(frozen=True)
class SyncedSet:
    """One message per channel of the groups present; `stamp_ns` is the newest of their stamps (the time at
    which all of the set's data exist)."""
    stamp_ns: int
    messages: dict
    stamps_ns: dict
    missing_groups: frozenset


class ApproximateTimeSynchronizer:
    """Feed messages with `add`; it returns the sets they complete. `channels`: hashable names; `groups`:
    channel → group name (default: each channel its own group); `queue_size`: messages kept per channel;
    `timeout_ns`: input-clock silence after which a group is left out (None: never); `restart_ns`: a message
    stamped more than this before the newest of its own channel means the input has started again (a bag
    played again, or looped): what is pending is flushed and matching starts afresh (None: never; the message
    would be dropped as one that crosses the sets). At least `reorder_window_ns`."""

    def __init__(self, channels, queue_size=10, max_interval_ns=None, groups=None, timeout_ns=None,
                 reorder_window_ns=0, restart_ns=None):
        self.channels = tuple(channels)
        self.groups = dict(groups) if groups is not None else {channel: channel for channel in self.channels}
        self.queue_size, self.max_interval_ns = queue_size, max_interval_ns
        self.timeout_ns, self.reorder_window_ns, self.restart_ns = timeout_ns, reorder_window_ns, restart_ns
        self.restarts = 0  # times the input started again
        if restart_ns is not None and restart_ns < reorder_window_ns:
            raise ValueError(f'restart_ns ({restart_ns}) must be at least reorder_window_ns ({reorder_window_ns})')
        self._channel_index = {channel: index for index, channel in enumerate(self.channels)}
        self._start()

    def _start(self):
        """The state of a synchroniser that has received nothing."""
        self._queues = {channel: [] for channel in self.channels}  # [(stamp, message)] sorted by stamp
        self._last_used_ns = {}  # channel → stamp of its message in the latest set
        self._group_heard_ns = {}  # group → newest stamp matched
        self._held = []  # heap of (stamp, channel index, arrival number, message) inside the reorder window
        self._arrivals = itertools.count()
        self._newest_ns = None  # newest stamp received
        self._channel_newest_ns = {}  # channel → its newest stamp received
        self._clock_ns = self._start_ns = None  # newest / first stamp matched
        self._ended = False  # within flush(): no message is still to come

    def add(self, channel, stamp_ns, message):
        """Take one message; return the sets completed by it, oldest first (often none, sometimes several)."""
        newest_ns = self._channel_newest_ns.get(channel)
        if self.restart_ns is not None and newest_ns is not None and stamp_ns < newest_ns - self.restart_ns:
            sets = self.flush()
            self._start()
            self.restarts += 1
            return sets + self.add(channel, stamp_ns, message)
        # The channel index and arrival number break stamp ties, so messages themselves are never compared.
        heapq.heappush(self._held, (stamp_ns, self._channel_index[channel], next(self._arrivals), message))
        self._channel_newest_ns[channel] = stamp_ns if newest_ns is None else max(newest_ns, stamp_ns)
        self._newest_ns = stamp_ns if self._newest_ns is None else max(self._newest_ns, stamp_ns)
        return self._match(self._newest_ns - self.reorder_window_ns)

    def flush(self):
        """The sets the messages received so far still make when no more come (the end of a bag, or every
        camera stopped): the reorder window's messages matched, then, as if every channel had ended, the
        candidate of each search published instead of waiting for a message that could prove it the
        narrowest, and cameras (groups) with no message left out as silent ones are (degraded sets); one
        that has sent only some of its channels' messages is waited for. Without it the newest set waits for
        the next message for ever: with jittered stamps ROS's ApproximateTime publishes a set only once
        every channel has a message past it. Later messages are taken as usual; a camera left out of a
        flushed set whose messages come after it forms a set of the same stamp (flush on real silence
        only: the nodes call it after camera_timeout without input)."""
        sets = self._match(None)
        self._ended = True
        try:
            return sets + self._ready_sets()
        finally:
            self._ended = False

    def _match(self, until_ns):
        """Move the held messages stamped up to until_ns (None: all) into the queues, in stamp order; the
        sets that completes."""
        sets = []
        while self._held and (until_ns is None or self._held[0][0] <= until_ns):
            stamp, index, _, held_message = heapq.heappop(self._held)
            self._enqueue(self.channels[index], stamp, held_message)
            sets += self._ready_sets()
        return sets

    def _ready_sets(self):
        """The sets the queues make now, oldest first, each taken out of them."""
        sets = []
        while (positions := self._search()) is not None:
            sets.append(self._publish(positions))
        return sets

    def _enqueue(self, channel, stamp_ns, message):
        if stamp_ns <= self._last_used_ns.get(channel, -1 << 63):
            return  # its channel already went past it: using it would cross the sets
        self._clock_ns = stamp_ns if self._clock_ns is None else max(self._clock_ns, stamp_ns)
        self._start_ns = stamp_ns if self._start_ns is None else self._start_ns
        group = self.groups[channel]
        self._group_heard_ns[group] = max(self._group_heard_ns.get(group, stamp_ns), stamp_ns)
        queue = self._queues[channel]
        position = bisect.bisect_left(queue, stamp_ns, key=lambda entry: entry[0])
        if position < len(queue) and queue[position][0] == stamp_ns:
            return  # a second message of a stamp this channel has: the first is kept (one per stamp and channel)
        queue.insert(position, (stamp_ns, message))
        if len(queue) > self.queue_size:
            del queue[0]

    def _silent(self, channel):
        """Whether the channel's group has not been heard for longer than the timeout (a group never heard
        counts from the first stamp matched)."""
        if self._ended:
            return True
        heard_ns = self._group_heard_ns.get(self.groups[channel], self._start_ns)
        return self.timeout_ns is not None and self._clock_ns - heard_ns > self.timeout_ns

    def _search(self):
        """ROS's candidate search: positions {channel: queue index} of the next set, or None while undecided.

        The first candidate is the queue fronts; its newest message is the pivot. The oldest front is then
        advanced one message at a time, keeping the candidate of smallest spread, until the pivot is the oldest
        front or the fronts have moved so far that every later candidate is wider. Rerun from the queue fronts
        after every new message, it reaches the same state as ROS's incremental version.
        """
        live = list(self.channels)
        positions = dict.fromkeys(live, 0)
        candidate = None
        while True:
            exhausted = [channel for channel in live if positions[channel] == len(self._queues[channel])]
            silent = [channel for channel in exhausted if self._silent(channel)]
            if silent and candidate is not None:
                return candidate  # a later candidate would need a message the silent channel will not send
            if exhausted and not silent:
                return None  # wait for messages
            if silent:  # no candidate yet, so all positions are 0: leave the silent groups out
                silent_groups = {self.groups[channel] for channel in silent}
                if self._ended and any(self._queues[c] for c in live if self.groups[c] in silent_groups):
                    return None  # a camera that has sent part of its messages is not silent: wait for the rest
                for channel in live:
                    if self.groups[channel] in silent_groups:
                        self._queues[channel].clear()  # an incomplete group's leftovers can never be used
                live = [channel for channel in live if self.groups[channel] not in silent_groups]
                positions = dict.fromkeys(live, 0)
                if not live:
                    return None
                continue
            fronts = {channel: self._queues[channel][positions[channel]][0] for channel in live}
            start, end = min(live, key=fronts.get), max(live, key=fronts.get)
            if candidate is None:
                if self.max_interval_ns is not None and fronts[end] - fronts[start] > self.max_interval_ns:
                    del self._queues[start][0]
                    continue
                candidate, pivot, pivot_ns = dict(positions), end, fronts[end]
                candidate_start_ns, candidate_end_ns = fronts[start], fronts[end]
            elif fronts[end] - candidate_end_ns < fronts[start] - candidate_start_ns:  # narrower
                candidate = dict(positions)
                candidate_start_ns, candidate_end_ns = fronts[start], fronts[end]
            positions[start] += 1
            # Later candidates keep the pivot and a front at least as new as `end`: if that alone is wider than
            # the candidate, none can beat it.
            if start == pivot or fronts[end] - pivot_ns >= candidate_end_ns - candidate_start_ns:
                return candidate

    def _publish(self, positions):
        """Take the set out of the queues, with every older message (a narrower set superseded them)."""
        messages, stamps_ns = {}, {}
        for channel, position in positions.items():
            stamps_ns[channel], messages[channel] = self._queues[channel][position]
            del self._queues[channel][:position + 1]
            self._last_used_ns[channel] = stamps_ns[channel]
        missing = frozenset(self.groups.values()) - {self.groups[channel] for channel in positions}
        return SyncedSet(max(stamps_ns.values()), messages, stamps_ns, missing)


class HeldSets:
    """Synchronised sets held, in order, until every camera they need is ready (its calibration has
    come), for at most `wait` seconds each; none is dropped: one that waited longer goes on without the
    camera, and a later set never overtakes an earlier one. At most `limit` are held (the oldest then
    goes on). Times are float [s] from one monotonic clock."""

    def __init__(self, wait, limit=100):
        self.wait, self.limit = wait, limit
        self.held = []   # [(arrival time, set)] in arrival (stamp) order

    def add(self, synced, now):
        self.held.append((now, synced))

    def release(self, now, ready):
        """The sets to handle now, in order: from the front, each that is ready (`ready(set)` is true),
        waited `wait` or more, or is beyond `limit`; the first that is none of these stops the release."""
        released = []
        while self.held:
            arrived, synced = self.held[0]
            if not (ready(synced) or now - arrived >= self.wait or len(self.held) > self.limit):
                break
            released.append(self.held.pop(0)[1])
        return released


class PendingSets:
    """The frame sets waiting for a slower worker (the fitter, in its own thread): at most `depth` (0: no
    limit). put() adds one; when that makes more than `depth`, the oldest waiting is skipped (and counted),
    so with depth 1 the worker always gets the newest set and no backlog builds up, whatever the input
    rate (real time). take() gets the oldest one still waiting."""

    def __init__(self, depth=1):
        self.depth = depth
        self._condition = threading.Condition()
        self._waiting = collections.deque()
        self.skipped = 0      # sets dropped unfitted because newer ones came
        self.closed = False

    def put(self, item):
        with self._condition:
            self._waiting.append(item)
            while self.depth and len(self._waiting) > self.depth:
                self._waiting.popleft()
                self.skipped += 1
            self._condition.notify()

    def __len__(self):
        """How many wait."""
        with self._condition:
            return len(self._waiting)

    def take(self, timeout):
        """The oldest waiting item, or None after `timeout` [s] without one, or once closed."""
        with self._condition:
            self._condition.wait_for(lambda: self._waiting or self.closed, timeout)
            return self._waiting.popleft() if self._waiting and not self.closed else None

    def close(self):
        with self._condition:
            self.closed = True
            self._condition.notify_all()


class Request(NamedTuple):
    """A frame request of FrameRequests: the announced SyncedSet asked for, its oldest stamp [ns], when it
    was asked [s], and whether this is its second asking (after one given up)."""
    synced: SyncedSet
    oldest_ns: int
    asked_at: float
    again: bool

    @classmethod
    def of(cls, synced, asked_at, again):
        """The Request of a SyncedSet asked at `asked_at`."""
        return cls(synced, min(synced.stamps_ns.values()), asked_at, again)


class FrameRequests:
    """Frame sets by request (real time without wasted work): the cameras announce each image's stamp, an
    ApproximateTimeSynchronizer makes sets of the announcements, and when the fitter is ready for another
    frame set (nothing waits before its stages) it asks the cameras for the newest announced set. The sets
    announced in between are skipped (counted) before any camera has computed their features, and every
    camera skips the same ones, so no camera's work is wasted on a set that another camera left out.

    One request is outstanding at a time: it is answered when a frame set at or after its oldest stamp
    arrives, and given up (counted) after `timeout` seconds without one, so a lost message or a camera
    that missed its image stalls the requests for that long only. A request given up is asked once more
    when nothing newer has been announced (a request lost at start-up, before a camera's subscription
    had matched, would otherwise leave a stream that has stopped, or the end of a bag, unfitted; the
    cameras hold their newest images). Times are float [s] from one monotonic clock; stamps int [ns]."""

    def __init__(self, timeout):
        self.timeout = timeout
        self.newest = None            # the newest announced SyncedSet not yet requested
        self.since_request = 0        # sets announced since the last request
        self.outstanding = None       # the Request waiting for its frame set
        self.skipped = 0              # announced sets never requested (a newer one was)
        self.unanswered = 0           # requests given up after `timeout`
        self.retry = None             # the SyncedSet of a request given up, to ask once more
        self._lock = threading.Lock()

    def announce(self, synced):
        """A SyncedSet of the cameras' announcements (stamps_ns keyed by channel, one per camera)."""
        with self._lock:
            self.newest = synced
            self.since_request += 1

    def received(self, stamp_ns):
        """A frame set of features came, stamped stamp_ns (the newest of its stamps)."""
        with self._lock:
            if self.outstanding is not None and stamp_ns >= self.outstanding.oldest_ns:
                self.outstanding = None
            if self.retry is not None and stamp_ns >= min(self.retry.stamps_ns.values()):
                self.retry = None   # the set given up came after all

    def next_request(self, now, ready):
        """The SyncedSet to request now, or None: while the consumer is not `ready`, a request is
        outstanding, or nothing new was announced and no request given up waits to be asked again."""
        with self._lock:
            if self.outstanding is not None and now - self.outstanding.asked_at > self.timeout:
                self.retry = None if self.outstanding.again else self.outstanding.synced
                self.outstanding = None
                self.unanswered += 1
            if not ready or self.outstanding is not None:
                return None
            if self.newest is not None:   # a newer set supersedes a retry
                self.outstanding = Request.of(self.newest, now, again=False)
                self.newest = self.retry = None
                self.skipped += self.since_request - 1
                self.since_request = 0
            elif self.retry is not None:
                self.outstanding, self.retry = Request.of(self.retry, now, again=True), None
            else:
                return None
            return self.outstanding.synced


def ready_to_request(waiting, busy_stages, overlap, starting=False):
    """Whether the fitter may ask the cameras for its next frame set (FrameRequests.next_request's `ready`):
    nothing waits before its stages (`waiting`, bool), and of its stages (busy_stages: bool per stage, first
    to last: distance maps, fit) at most the last `overlap` are still busy with the sets before. Overlapping
    more fits more frame sets when there are cores to spare, and delays each one more when there are not
    (the skeleton_fitter's request_overlap). `starting`: the last stage's set starts the fit
    (SkeletonFitter.starts_next), which fits every labelling of the body, several fits' time: a set asked
    for meanwhile would wait behind it, and its features would take cores from it, so none is asked for
    until every stage is free (at 1× on 2 cores the first fits' latency fell from about 300 to 200 ms)."""
    if starting:
        overlap = 0
    return not waiting and not any(busy_stages[:len(busy_stages) - overlap])
