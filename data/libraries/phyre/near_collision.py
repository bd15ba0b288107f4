"""near collision: two balls, at least one moving at MOVING_V px/s or more, pass within NEAR_GAP px
(surface to surface) of each other without touching. Span: the frames of the close pass."""

MOVING_V = 20.0
NEAR_GAP = 8.0
MIN_GAP = 1.5


def _gaps(kp, cp, kq, cq):
    """The surface gaps of two balls at the steps both have, in ball p's step order, from each ball's
    (x, y, diameter) per step (cp, cq: aligned with its step list kp, kq; a step listed twice holds the
    object the step's last entry gives)."""
    if kp == kq:
        return kp, [((ax - bx) ** 2 + (ay - by) ** 2) ** 0.5 - (ad + bd) / 2.0
                    for (ax, ay, ad), (bx, by, bd) in zip(cp, cq)]
    at_q = dict(zip(kq, cq))
    ks, gaps = [], []
    for k, (ax, ay, ad) in zip(kp, cp):
        b = at_q.get(k)
        if b is None:
            continue
        bx, by, bd = b
        ks.append(k)
        gaps.append(((ax - bx) ** 2 + (ay - by) ** 2) ** 0.5 - (ad + bd) / 2.0)
    return ks, gaps


def find_pattern(trace):
    if not trace.get("timesteps"):
        return []
    idx, ts = _clock(trace)
    kin = _kin(trace)
    contacts = _contacts(trace)
    balls = sorted(o for o in kin if kin[o]["o"][0].get("shape") == "ball")
    out = []
    at = {b: dict(zip(kin[b]["k"], kin[b]["o"])) for b in balls}
    # Each ball's position and size per step, read once (not once per pair). Where an object cannot
    # be read so, or a gap overflows, the pair loop below reads the objects itself, as it always did,
    # so a malformed trace fails (or not) exactly where it did.
    try:
        xyd = {b: [(float(o["x"]), float(o["y"]), float(o["diameter"])) for o in [at[b][k] for k in kin[b]["k"]]]
               for b in balls}
    except (KeyError, TypeError, ValueError, OverflowError):
        xyd = None
    for i, p in enumerate(balls):
        for q in balls[i + 1:]:
            key = tuple(sorted((p, q)))
            ks, flags, gaps = None, [], []
            if xyd is not None:
                try:
                    ks, gaps = _gaps(kin[p]["k"], xyd[p], kin[q]["k"], xyd[q])
                except OverflowError:
                    ks, gaps = None, []
            if ks is not None:
                # No step within NEAR_GAP (NaN gaps flag nothing either): no run, so no pattern.
                if not gaps or min(gaps) > NEAR_GAP:
                    continue
                flags = [MIN_GAP < gap <= NEAR_GAP and max(_speed_at(kin, p, k), _speed_at(kin, q, k)) >= MOVING_V
                         for k, gap in zip(ks, gaps)]
            else:
                ks = []
                for k in kin[p]["k"]:
                    op, oq = at[p][k], at[q].get(k)
                    if oq is None:
                        continue
                    d = ((float(op["x"]) - float(oq["x"])) ** 2 + (float(op["y"]) - float(oq["y"])) ** 2) ** 0.5
                    gap = d - (float(op["diameter"]) + float(oq["diameter"])) / 2.0
                    ks.append(k)
                    gaps.append(gap)
                    flags.append(MIN_GAP < gap <= NEAR_GAP and max(_speed_at(kin, p, k), _speed_at(kin, q, k)) >= MOVING_V)
            for a_, b_ in _runs(ks, ts, flags, 0.0):
                a, b = ks[a_], ks[b_]
                if any(g["pair"] == key and g["t0"] <= ts[b] + 0.2 and g["t1"] >= ts[a] - 0.2 for g in contacts):
                    continue
                out.append({"label": "near collision", "start_timestep": idx[a], "end_timestep": idx[b],
                            "parameters": {"object_details": {p: _detail(trace, a, b, p, "passing object"),
                                                              q: _detail(trace, a, b, q, "passing object")},
                                           "min_gap_px": round(min(gaps[a_:b_ + 1]), 2)}})
    return out
