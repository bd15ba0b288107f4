"""bounce: a body hits something and rebounds: at a contact begin its vertical velocity is downward at
at least DOWN_V px/s in the frame before and upward at at least UP_V px/s in a frame within AFTER_S
after (or the reverse for hits from below). Span: frame before to the rebound frame."""

DOWN_V = 20.0
UP_V = 10.0
AFTER_S = 0.2


def find_pattern(trace):
    if not trace.get("timesteps"):
        return []
    idx, ts = _clock(trace)
    kin = _kin(trace)
    out = []
    for g in _contacts(trace):
        pre = _at(ts, g["t0"] - 1e-9)
        for me in g["pair"]:
            if me not in kin or _is_static(kin, me):
                continue
            v0 = _vel(kin, me, pre)[1]
            if abs(v0) < DOWN_V:
                continue
            k, hit = pre + 1, None
            while k < len(ts) and ts[k] <= g["t0"] + AFTER_S:
                v1 = _vel(kin, me, k)[1]
                if v1 * v0 < 0 and abs(v1) >= UP_V:
                    hit = k
                    break
                k += 1
            if hit is None:
                continue
            other = g["pair"][0] if g["pair"][1] == me else g["pair"][1]
            out.append({"label": "bounce", "start_timestep": idx[pre], "end_timestep": idx[hit],
                        "parameters": {"object_details": {me: _detail(trace, pre, hit, me, "bouncing object"),
                                                          other: _detail(trace, pre, hit, other, "surface bounced off")},
                                       "speed_in": round(abs(v0), 1), "speed_out": round(abs(_vel(kin, me, hit)[1]), 1),
                                       "t": round(g["t0"], 4)}})
    return out
