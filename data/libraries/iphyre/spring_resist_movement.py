"""spring resist movement: a spring holds back two objects moving apart, slowing their separation.

For each spring pair, runs of frames in which their centre distance grows at at least RATE_V px/s while
the growth rate falls (the spring decelerates the separation) by at least DECEL px/s² on average, lasting
at least MIN_S. Parameters: distance at start and end (px), separation speed at start and end (px/s).
"""

RATE_V = 10.0
DECEL = 5.0
MIN_S = 0.1


def find_pattern(trace):
    if not trace.get("timesteps"):
        return []
    idx, ts = _clock(trace)
    kin = _kin(trace)
    out = []
    for s, p, q, ks, ds, rs in _spring_series(trace, kin):
        flags = []
        for n in range(len(ks)):
            m = max(n - 1, 0)
            dt = ts[ks[n]] - ts[ks[m]]
            slowing = dt > 0.0 and (rs[m] - rs[n]) / dt >= DECEL
            flags.append(rs[n] >= RATE_V and slowing)
        for i, j in _runs(ks, ts, flags, MIN_S):
            a, b = ks[i], ks[j]
            out.append({"label": "spring resist movement", "start_timestep": idx[a], "end_timestep": idx[b],
                        "parameters": {"object_details": {p: _detail(trace, a, b, p, "restrained object"),
                                                          q: _detail(trace, a, b, q, "restrained object")},
                                       "spring": s, "distance_start_px": round(ds[i], 1),
                                       "distance_end_px": round(ds[j], 1),
                                       "separation_speed_start": round(rs[i], 1),
                                       "separation_speed_end": round(rs[j], 1)}})
    return out
