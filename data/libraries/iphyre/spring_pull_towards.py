"""spring pull towards: a spring draws the two objects it joins towards each other.

For each spring pair, runs of frames in which their centre distance shrinks at at least RATE_V px/s,
lasting at least MIN_S and closing at least MIN_CLOSE px. Parameters: distance at start and end (px), peak
closing speed (px/s).
"""

RATE_V = 10.0
MIN_S = 0.1
MIN_CLOSE = 3.0


def find_pattern(trace):
    if not trace.get("timesteps"):
        return []
    idx, ts = _clock(trace)
    kin = _kin(trace)
    out = []
    for s, p, q, ks, ds, rs in _spring_series(trace, kin):
        for i, j in _runs(ks, ts, [r <= -RATE_V for r in rs], MIN_S):
            if ds[i] - ds[j] < MIN_CLOSE:
                continue
            a, b = ks[i], ks[j]
            out.append({"label": "spring pull towards", "start_timestep": idx[a], "end_timestep": idx[b],
                        "parameters": {"object_details": {p: _detail(trace, a, b, p, "pulled object"),
                                                          q: _detail(trace, a, b, q, "pulled object")},
                                       "spring": s, "distance_start_px": round(ds[i], 1),
                                       "distance_end_px": round(ds[j], 1),
                                       "peak_closing_speed": round(-min(rs[i:j + 1]), 1)}})
    return out
