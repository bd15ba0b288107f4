"""bounce: an object hits another and rebounds, its velocity along the contact normal reversing.

At each contact begin (chatter merged), for each dynamic object of the pair: its velocity relative to
the other along the contact normal approaches at least APPROACH_V px/s in the frame before, and within
AFTER_S after the contact it separates along that normal at at least REBOUND_FRAC of the approach speed
and at least MIN_REBOUND_V px/s. I-PHYRE's shapes are nearly inelastic (effective restitution 0.01), so
bounces come from rotating or sprung bodies and off moving objects. The pattern spans the step before the
contact to the step of the rebound peak.
"""

APPROACH_V = 20.0
REBOUND_FRAC = 0.2
MIN_REBOUND_V = 5.0
AFTER_S = 0.15


def find_pattern(trace):
    if not trace.get("timesteps"):
        return []
    idx, ts = _clock(trace)
    kin = _kin(trace)
    out = []
    for g in _contacts(trace):
        c = _at(ts, g["t0"])
        pre = max(c - 1, 0)
        for me, other in (g["pair"], g["pair"][::-1]):
            if me not in kin or other not in kin or not kin[me]["o"][0].get("dynamic"):
                continue
            om, oo = _obj_at(trace, c, me), _obj_at(trace, c, other)
            if om is None or oo is None:
                continue
            nx, ny = _normal(oo, om)  # from the other towards me
            v1, v2 = _vel(kin, me, pre), _vel(kin, other, pre)
            approach = -((v1[0] - v2[0]) * nx + (v1[1] - v2[1]) * ny)
            if approach < APPROACH_V:
                continue
            best, kbest = 0.0, None
            k = c
            while k < len(ts) and ts[k] <= ts[c] + AFTER_S:
                if _obj_at(trace, k, me) is None or _obj_at(trace, k, other) is None:
                    break
                w1, w2 = _vel(kin, me, k), _vel(kin, other, k)
                sep = (w1[0] - w2[0]) * nx + (w1[1] - w2[1]) * ny
                if sep > best:
                    best, kbest = sep, k
                k += 1
            if kbest is None or best < MIN_REBOUND_V or best < REBOUND_FRAC * approach:
                continue
            params = {"object_details": {me: _detail(trace, pre, kbest, me, "bouncing object"),
                                         other: _detail(trace, pre, kbest, other, "surface bounced off")},
                      "approach_speed": round(approach, 1), "rebound_speed": round(best, 1),
                      "restitution": round(best / approach, 3), "t": round(g["t0"], 4)}
            out.append({"label": "bounce", "start_timestep": idx[pre], "end_timestep": idx[kbest],
                        "parameters": params})
    return out
