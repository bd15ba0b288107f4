"""sliding ball: a ball slides over the cloth (its contact point slips), from the strike, collision or
cushion contact that sets it sliding until it starts to roll (or drops into a pocket).

One pattern per episode; further contacts while the ball is still sliding extend the episode."""


MERGE_S = 0.05


STARTS = ("physics_stick_ball", "physics_ball_ball", "physics_ball_linear_cushion",
          "physics_ball_circular_cushion")
ENDS = ("physics_sliding_rolling", "physics_ball_pocket")


def find_pattern(trace):
    if not trace.get("timesteps"):
        return []
    idx, ts = _clock(trace)
    out = []
    for bid, t0, t1 in _episodes(trace, STARTS, ENDS, "sliding"):
        if t1 <= t0:
            continue
        s, e, a, b = _span(idx, ts, t0, t1)
        out.append({"label": "sliding ball", "start_timestep": s, "end_timestep": e,
                    "parameters": {"object_details": {bid: _detail(trace, a, b, bid, "sliding ball")},
                                   "t_start": round(t0, 4), "t_end": round(t1, 4)}})
    return out
