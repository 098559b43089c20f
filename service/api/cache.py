"""A bounded in-process LRU cache of decoded clips, so frame requests skip blob reads and decoding."""

from __future__ import annotations

import threading
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any


@dataclass(frozen=True)
class CachedClip:
    """A decoded clip with the row fields the routes need (owner, blob keys) and its frame writer."""

    tenant_id: str
    coefficients_key: str
    topology_key: str
    clip: Any  # pdeanim.clip.Clip
    frame_glb: Any  # pdeanim.gltf.write.FrameGlb of the clip's topology: positions (V, 3) -> GLB bytes


class ClipCache:
    """LRU of at most ``max_entries`` clips; loading happens outside the lock (a duplicate load is harmless)."""

    def __init__(self, max_entries: int):
        self.max_entries = max(1, int(max_entries))
        self._items: OrderedDict[str, CachedClip] = OrderedDict()
        self._lock = threading.Lock()
        self.hits = self.misses = 0

    def get(self, clip_id: str, load: Callable[[], CachedClip]) -> CachedClip:
        """The cached clip, or ``load()`` it and keep it, evicting the least recently used."""
        with self._lock:
            item = self._items.get(clip_id)
            if item is not None:
                self._items.move_to_end(clip_id)
                self.hits += 1
                return item
            self.misses += 1
        item = load()
        with self._lock:
            self._items[clip_id] = item
            self._items.move_to_end(clip_id)
            while len(self._items) > self.max_entries:
                self._items.popitem(last=False)
        return item

    def evict(self, clip_id: str) -> None:
        """Forget a clip (deleted), so this process answers 404 for it from now on."""
        with self._lock:
            self._items.pop(clip_id, None)

    def __len__(self) -> int:
        return len(self._items)
