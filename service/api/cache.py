"""Bounded in-process LRU caches of the frame route: decoded clips (so frame requests skip blob reads and
decoding) and encoded frame bodies per (clip, t) (players ask for the same t values at a fixed rate)."""

from __future__ import annotations

import threading
from collections import OrderedDict
from collections.abc import Callable, Hashable
from dataclasses import dataclass
from typing import Any

import numpy as np


@dataclass(frozen=True)
class CachedClip:
    """A decoded clip with the row fields the routes need (owner, blob keys) and its frame writer."""

    tenant_id: str
    coefficients_key: str
    topology_key: str
    clip: Any  # pdeanim.clip.Clip
    frame_glb: Any  # pdeanim.gltf.write.FrameGlb of the clip's topology: positions (V, 3) -> GLB bytes

    @property
    def nbytes(self) -> int:
        """Memory of the clip's arrays (a dense clip's evaluation tables: (S+1) x V x 3 floats)."""
        return array_bytes(self.clip) + array_bytes(self.frame_glb)


def array_bytes(obj: Any, depth: int = 3) -> int:
    """Bytes of the numpy arrays held by ``obj``'s attributes (and their attributes, lists and dicts, down to
    ``depth`` levels); shared arrays count once."""
    seen: set[int] = set()

    def walk(x: Any, level: int) -> int:
        if isinstance(x, np.ndarray):
            base = x if x.base is None else x.base
            if id(base) in seen:
                return 0
            seen.add(id(base))
            return int(getattr(base, "nbytes", x.nbytes))
        if level <= 0 or isinstance(x, (str, bytes, int, float, bool)) or x is None:
            return 0
        if isinstance(x, dict):
            return sum(walk(v, level - 1) for v in x.values())
        if isinstance(x, (list, tuple)):
            return sum(walk(v, level - 1) for v in x)
        attrs = getattr(x, "__dict__", None)
        return sum(walk(v, level - 1) for v in attrs.values()) if attrs else 0

    return walk(obj, depth)


class _Loading:
    """A clip being loaded: the requests that want it meanwhile wait on ``done`` instead of loading it."""

    def __init__(self) -> None:
        self.done = threading.Event()
        self.item: CachedClip | None = None
        self.error: BaseException | None = None


class ClipCache:
    """LRU of at most ``max_entries`` clips holding at most ``max_bytes`` of arrays in total, by construction:
    the least recently used are evicted before a clip is inserted, and a clip larger than ``max_bytes`` alone
    is served to the requests that loaded it but never kept. A clip is loaded once however many requests ask
    for it meanwhile (they wait for that load; other clips' requests go on), outside the lock. Ids marked gone
    (deleted, seen by this process or by :class:`pdeanim_service.api.invalidation.DeletionWatch`) are never
    kept again."""

    def __init__(self, max_entries: int, max_bytes: int = 0, max_gone: int = 100_000):
        self.max_entries = max(1, int(max_entries))
        self.max_bytes = max(0, int(max_bytes))  # 0: no byte bound
        self.max_gone = max(1, int(max_gone))
        self._items: OrderedDict[str, CachedClip] = OrderedDict()
        self._sizes: dict[str, int] = {}
        self._size = 0
        self._loading: dict[str, _Loading] = {}
        self._gone: OrderedDict[str, None] = OrderedDict()
        self._lock = threading.Lock()
        self.hits = self.misses = 0
        self.too_large = 0  # loads served but not kept: larger than max_bytes alone

    def peek(self, clip_id: str) -> CachedClip | None:
        """The cached clip (marked recently used) or None, without loading: no I/O, safe on the event loop."""
        with self._lock:
            item = self._items.get(clip_id)
            if item is not None:
                self._items.move_to_end(clip_id)
                self.hits += 1
            return item

    def get(self, clip_id: str, load: Callable[[], CachedClip]) -> CachedClip:
        """The cached clip, or ``load()`` it (once, whoever else asks meanwhile) and keep it, evicting the
        least recently used; a load's exception reaches every request that waited for it."""
        with self._lock:
            item = self._items.get(clip_id)
            if item is not None:
                self._items.move_to_end(clip_id)
                self.hits += 1
                return item
            pending = self._loading.get(clip_id)
            owner = pending is None
            if owner:
                pending = self._loading[clip_id] = _Loading()
                self.misses += 1
        if not owner:
            pending.done.wait()
            if pending.error is not None:
                raise pending.error
            return pending.item
        try:
            pending.item = load()
        except BaseException as exc:
            pending.error = exc
            raise
        finally:
            self._finish(clip_id, pending)
        return pending.item

    def _finish(self, clip_id: str, pending: _Loading) -> None:
        """Keep a finished load (unless it failed, the clip was marked gone meanwhile, or it alone is over the
        byte limit), evicting the least recently used first so the cache never holds more than its limit;
        wake its waiters."""
        item = pending.item
        size = item.nbytes if self.max_bytes and item is not None else 0
        with self._lock:
            self._loading.pop(clip_id, None)
            fits = not self.max_bytes or size <= self.max_bytes
            if pending.error is None and item is not None and clip_id not in self._gone and fits:
                self._drop(clip_id)
                while self._items and (len(self._items) + 1 > self.max_entries or (
                        self.max_bytes and self._size + size > self.max_bytes)):
                    self._drop(next(iter(self._items)))
                self._items[clip_id] = item
                self._sizes[clip_id] = size
                self._size += size
            elif item is not None and not fits:
                self.too_large += 1
        pending.done.set()

    def _drop(self, clip_id: str) -> None:
        if self._items.pop(clip_id, None) is not None:
            self._size -= self._sizes.pop(clip_id, 0)

    def evict(self, clip_id: str) -> None:
        """Forget a deleted clip, so this process answers 404 for it from now on."""
        self.forget([clip_id])

    def forget(self, clip_ids: list[str]) -> None:
        """Drop deleted clips and mark them gone: a load of one in flight now is not kept, and
        :meth:`is_gone` says so to the request that made it."""
        with self._lock:
            for clip_id in clip_ids:
                self._drop(clip_id)
                self._gone[clip_id] = None
                self._gone.move_to_end(clip_id)
            while len(self._gone) > self.max_gone:
                self._gone.popitem(last=False)

    def is_gone(self, clip_id: str) -> bool:
        """Whether the clip was found deleted (no I/O)."""
        return clip_id in self._gone

    def tracked(self) -> list[str]:
        """Ids of the clips cached or being loaded: the ones whose deletion this process must notice."""
        with self._lock:
            return [*self._items, *self._loading]

    def size(self) -> int:
        """Bytes of the cached clips' arrays (0 when the cache has no byte bound)."""
        return self._size

    def __len__(self) -> int:
        return len(self._items)


class BodyCache:
    """LRU of encoded response bodies (immutable ``bytes``) holding at most ``max_bytes`` in total; a body
    larger than a quarter of that is not kept. ``max_bytes`` 0 disables it."""

    def __init__(self, max_bytes: int):
        self.max_bytes = max(0, int(max_bytes))
        self._items: OrderedDict[Hashable, bytes] = OrderedDict()
        self._size = 0
        self._lock = threading.Lock()
        self.hits = self.misses = 0

    def get(self, key: Hashable) -> bytes | None:
        """The body stored under ``key`` (marked recently used), or None."""
        with self._lock:
            body = self._items.get(key)
            if body is None:
                self.misses += 1
                return None
            self._items.move_to_end(key)
            self.hits += 1
            return body

    def put(self, key: Hashable, body: bytes) -> None:
        """Keep ``body`` under ``key``, evicting the least recently used bodies beyond ``max_bytes``."""
        if len(body) * 4 > self.max_bytes:
            return
        with self._lock:
            old = self._items.pop(key, None)
            self._size += len(body) - (len(old) if old is not None else 0)
            self._items[key] = body
            while self._size > self.max_bytes:
                _, evicted = self._items.popitem(last=False)
                self._size -= len(evicted)

    def drop_where(self, match: Callable[[Hashable], bool]) -> int:
        """Remove the bodies whose key ``match``es (a deleted clip's frames); returns how many."""
        with self._lock:
            keys = [k for k in self._items if match(k)]
            for k in keys:
                self._size -= len(self._items.pop(k))
        return len(keys)

    @property
    def size(self) -> int:
        """Bytes held."""
        return self._size

    def __len__(self) -> int:
        return len(self._items)
