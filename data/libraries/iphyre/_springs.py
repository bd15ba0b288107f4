"""Prelude: spring pairs (objects sharing a nonzero `spring` id) and, per shared frame, their centre
distance and its rate of change (relative velocity along the line of centres, from the recorded or
derived velocities, so uneven frame spacing does not matter).

library.toml prepends it to the detectors that list it; it defines no find_pattern."""


def _spring_series(trace, kin):
    """[(spring id, a, b, [timestep positions], [distance], [rate])] per spring pair."""
    springs = {}
    for oid, m in kin.items():
        s = m["o"][0].get("spring")
        if s:
            springs.setdefault(s, []).append(oid)
    out = []
    for s, ids in sorted(springs.items()):
        if len(ids) != 2:
            continue
        a, b = sorted(ids)
        kb = set(kin[b]["k"])
        ks = [k for k in kin[a]["k"] if k in kb]
        ds, rs = [], []
        for k in ks:
            ca, cb = _centre(_obj_at(trace, k, a)), _centre(_obj_at(trace, k, b))
            dx, dy = cb[0] - ca[0], cb[1] - ca[1]
            d = (dx * dx + dy * dy) ** 0.5
            va, vb = _vel(kin, a, k), _vel(kin, b, k)
            r = 0.0 if d <= 0.0 else ((vb[0] - va[0]) * dx + (vb[1] - va[1]) * dy) / d
            ds.append(d)
            rs.append(r)
        out.append((s, a, b, ks, ds, rs))
    return out
