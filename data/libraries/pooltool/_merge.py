"""Prelude: Merging of same-pair contacts closer than 50 ms (the paper's chattering-contacts fault).

library.toml prepends it to the detectors that list it; it defines no find_pattern."""


def _merge(events, key):
    """Merges events with the same key closer than MERGE_S seconds (a chattering contact is one
    collision). Returns groups {key, t0, t1, n, payloads} in time order."""
    last, out = {}, []
    for t, p in events:
        k = key(p)
        if k is None:
            continue
        g = last.get(k)
        if g is not None and t - g["t1"] <= MERGE_S:
            g["t1"] = t
            g["n"] += 1
            g["payloads"].append(p)
        else:
            g = {"key": k, "t0": t, "t1": t, "n": 1, "payloads": [p]}
            last[k] = g
            out.append(g)
    return out
