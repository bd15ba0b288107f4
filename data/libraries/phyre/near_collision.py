"""near collision: two balls, at least one moving at MOVING_V px/s or more, pass within NEAR_GAP px
(surface to surface) of each other without touching. Span: the frames of the close pass."""

MOVING_V = 20.0
NEAR_GAP = 8.0
MIN_GAP = 1.5


def find_pattern(trace):
    if not trace.get("timesteps"):
        return []
    idx, ts = _clock(trace)
    kin = _kin(trace)
    contacts = _contacts(trace)
    balls = sorted(o for o in kin if kin[o]["o"][0].get("shape") == "ball")
    out = []
    at = {b: dict(zip(kin[b]["k"], kin[b]["o"])) for b in balls}
    for i, p in enumerate(balls):
        for q in balls[i + 1:]:
            key = tuple(sorted((p, q)))
            ks, flags, gaps = [], [], []
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
