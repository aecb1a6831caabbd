"""The order in which one camera's marker tracker takes its inputs, without ROS (the marker_tracker
node's wiring uses these; their rules are tested on their own).

Two races need rules:
- `LabelledStart`: the tracker starts from the operator's labelled calibration frame (paper 001), which
  arrives on its own topic. The labelling and its image (same stamp) can come in either order, so each
  waits a little for the other: the last few images are held until their labelling comes, the last
  labellings until their image comes.
- `FusedTurns`: with marker_skeleton running, each image is tracked only after the fused tracks of the
  previous one came back (the tracker continues from them), or after `fused_wait` seconds, or at once
  while nobody publishes fused tracks. Images that arrive meanwhile queue up (a bounded queue).
Items are opaque to both classes (the node passes (rgb, header) pairs); stamps are int [ns]; times are
float [s] from one monotonic clock.
"""
import collections

LABELLINGS_KEPT = 50       # labellings kept while waiting for the image of the same stamp
WAITING_IMAGES_KEPT = 3    # images kept while waiting for the labelling of the same stamp
QUEUED_IMAGES_KEPT = 100   # images kept while waiting for the fused tracks of the previous one


class LabelledStart:
    """Pairs the first tracked image with its labelling by stamp, whichever comes first."""

    def __init__(self, labellings_kept=LABELLINGS_KEPT, images_kept=WAITING_IMAGES_KEPT):
        self.labellings_kept, self.images_kept = labellings_kept, images_kept
        self.labellings = {}   # stamp -> labelling
        self.waiting = {}      # stamp -> image item, seen before its labelling

    def add_labelling(self, stamp, labelling):
        """Keep a labelling; the held image items it releases, in stamp order: its own image and the
        later ones (earlier ones can no longer be tracked from it), or [] when its image has not come."""
        self.labellings[stamp] = labelling
        while len(self.labellings) > self.labellings_kept:
            del self.labellings[min(self.labellings)]
        if stamp not in self.waiting:
            return []
        released = [item for held, item in sorted(self.waiting.items()) if held >= stamp]
        self.waiting = {}
        return released

    def labelling_for(self, stamp, item):
        """The labelling of an image item's stamp, or None, in which case the item is held (the oldest
        held item is forgotten beyond images_kept)."""
        labelling = self.labellings.get(stamp)
        if labelling is None:
            self.waiting[stamp] = item
            while len(self.waiting) > self.images_kept:
                del self.waiting[min(self.waiting)]
        return labelling

    def reject(self, stamp):
        """Forget a labelling that turned out unusable."""
        self.labellings.pop(stamp, None)

    def started(self):
        """The tracker started: nothing more is held."""
        self.labellings, self.waiting = {}, {}


class FusedTurns:
    """Images in turn, each after the fused tracks of the one before (or fused_wait [s], or at once
    while no one publishes them)."""

    def __init__(self, fused_wait, queue_kept=QUEUED_IMAGES_KEPT):
        self.fused_wait = fused_wait
        self.queue = collections.deque()
        self.queue_kept = queue_kept
        self.awaited = None   # (stamp of the last tracks sent, when they were sent) until their fusion comes

    def push(self, item):
        """Queue an item; whether the oldest queued item had to be dropped to keep queue_kept."""
        self.queue.append(item)
        if len(self.queue) > self.queue_kept:
            self.queue.popleft()
            return True
        return False

    def next_item(self, now, fusion_published):
        """The next item to track now, or None: none queued, or the last tracks' fusion is still awaited
        (within fused_wait of sending, while `fusion_published` says someone publishes fused tracks)."""
        if not self.queue:
            return None
        if self.awaited is not None and now - self.awaited[1] < self.fused_wait and fusion_published:
            return None
        return self.queue.popleft()

    def sent(self, stamp, now):
        """The tracks of `stamp` were published at `now`: the next item waits for their fusion."""
        self.awaited = (stamp, now)

    def fused(self, stamp):
        """Fused tracks of `stamp` came: True when they are the awaited ones (the tracker continues from
        them and the next item may go), False when late or not awaited."""
        if self.awaited is None or stamp != self.awaited[0]:
            return False
        self.awaited = None
        return True
