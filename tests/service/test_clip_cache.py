"""The decoded-clip cache of the API processes: bounded by entries and by the memory of the clips' arrays
(a dense clip's evaluation tables grow with segments x vertices)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from pdeanim.clip import load_clip_file
from pdeanim.gltf.write import FrameGlb
from pdeanim_service.api.cache import CachedClip, ClipCache, array_bytes

FIXTURES = Path(__file__).resolve().parents[2] / "clients" / "js" / "test" / "fixtures"


def _item(name: str) -> CachedClip:
    clip = load_clip_file(FIXTURES / name)
    return CachedClip("tenant", f"key-{name}", f"topo-{name}", clip, FrameGlb(clip.faces, clip.n_vertices))


def test_array_bytes_counts_the_evaluation_tables_once():
    item = _item("fit-blend-displacement-chord-loop-basis.clip")
    fields = item.clip._knot_fields  # (S+1, V*3) float32: the table that grows with segments x vertices
    assert fields.nbytes > 0
    assert item.nbytes >= fields.nbytes
    shared = np.zeros(1000)
    assert array_bytes({"a": shared, "b": [shared, shared[10:]]}) == shared.nbytes


def test_the_cache_never_holds_more_than_its_bytes_and_never_keeps_a_clip_larger_than_them():
    names = ["fit-blend-displacement-chord-loop-basis.clip", "synthetic-blend-displacement-paper-basis.clip",
             "synthetic-blend-rigid-chord-loop-basis.clip"]
    items = {n: _item(n) for n in names}
    smallest = min(i.nbytes for i in items.values())
    largest = max(i.nbytes for i in items.values())
    cache = ClipCache(max_entries=32, max_bytes=largest)  # room for the newest, whichever it is
    for n in names:
        assert cache.get(n, lambda n=n: items[n]) is items[n]
        assert cache.peek(n) is items[n] and cache.size() <= largest
    tiny = ClipCache(max_entries=32, max_bytes=1)  # below any clip: served to its request, never kept
    assert tiny.get(names[0], lambda: items[names[0]]) is items[names[0]]
    assert len(tiny) == 0 and tiny.size() == 0 and tiny.too_large == 1 and tiny.peek(names[0]) is None
    total = sum(i.nbytes for i in items.values())
    for limit in range(smallest - 1, total + 2, max(1, (total - smallest) // 7)):  # every order, every size
        bounded = ClipCache(max_entries=2, max_bytes=limit)
        for n in [*names, *reversed(names), names[1]]:
            bounded.get(n, lambda n=n: items[n])
            assert bounded.size() <= limit and len(bounded) <= 2
            assert bounded.size() == sum(items[k].nbytes for k in names if bounded.peek(k) is not None)
    roomy = ClipCache(max_entries=2, max_bytes=0)  # no byte bound: the entry count still applies
    for n in names:
        roomy.get(n, lambda n=n: items[n])
    assert len(roomy) == 2 and roomy.peek(names[0]) is None and roomy.size() == 0
    for n in names:
        cache.evict(n)
    assert len(cache) == 0 and cache.size() == 0
