"""Prelude: per-object motion helpers: runs of frames where a condition holds (gaps up to MERGE_S
bridged, runs shorter than a minimum dropped), on-screen test, contact normals and segment directions.

library.toml prepends it to the detectors that list it; it defines no find_pattern."""

SCREEN = 600.0


def _runs(ks, ts, flags, min_s, gap=MERGE_S):
    """Runs of track entries whose flag is true, as (first entry, last entry); runs separated by at most
    `gap` (default MERGE_S) are joined; runs lasting less than min_s are dropped. Frame times accumulate
    float error (8.3 - 8.2 < 0.1), so both comparisons allow 1e-9 s, as the ground truth's runs do."""
    out = []
    for i, f in enumerate(flags):
        if not f:
            continue
        if out and (i == out[-1][1] + 1 or ts[ks[i]] - ts[ks[out[-1][1]]] <= gap + 1e-9):
            out[-1][1] = i
        else:
            out.append([i, i])
    return [(a, b) for a, b in out if ts[ks[b]] - ts[ks[a]] >= min_s - 1e-9]


def _on_screen(o):
    c = _centre(o)
    r = float(o.get("radius", 0.0))
    return -r <= c[1] <= SCREEN + r and -r <= c[0] <= SCREEN + r


def _normal(o_from, o_to):
    """Unit vector from o_from's closest point towards o_to's (centre to centre if they overlap)."""
    p, q, d = _closest(o_from, o_to)
    if d < 1e-6:
        p, q = _centre(o_from), _centre(o_to)
        d = ((q[0] - p[0]) ** 2 + (q[1] - p[1]) ** 2) ** 0.5
        if d < 1e-6:
            return (0.0, -1.0)
    return ((q[0] - p[0]) / d, (q[1] - p[1]) / d)


def _vel(kin, oid, k):
    if oid not in kin:
        return (0.0, 0.0)
    return kin[oid]["v"][_entry(kin, oid, k)]


def _spin(kin, oid, k, ts):
    """Angular velocity (rad/s, y down: positive clockwise on screen): recorded, else from the change
    of the segment's direction over the real time between frames (0 for balls without a record)."""
    e = _entry(kin, oid, k)
    o = kin[oid]["o"][e]
    if o.get("angular_velocity") is not None:
        return float(o["angular_velocity"])
    ks, os_ = kin[oid]["k"], kin[oid]["o"]
    a, b = max(e - 1, 0), min(e + 1, len(ks) - 1)
    dt = ts[ks[b]] - ts[ks[a]]
    if a == b or dt <= 0.0 or _is_ball(o):
        return 0.0
    u = (os_[a]["x2"] - os_[a]["x1"], os_[a]["y2"] - os_[a]["y1"])
    w = (os_[b]["x2"] - os_[b]["x1"], os_[b]["y2"] - os_[b]["y1"])
    nu = (u[0] ** 2 + u[1] ** 2) ** 0.5 * (w[0] ** 2 + w[1] ** 2) ** 0.5
    if nu <= 0.0:
        return 0.0
    return (u[0] * w[1] - u[1] * w[0]) / nu / dt
