"""Prelude: Motion-state episodes per ball, for the state labels (rolling, sliding, spinning, slowing).

library.toml prepends it to the detectors that list it; it defines no find_pattern."""


def _balls_of(kind, p):
    """Ball ids an event involves (cushion and pocket ids are not balls; `_roles`)."""
    return _roles(kind, p)[0]


def _episodes(trace, starts, ends, state_name):
    """Per-ball episodes of a motion state, from the event log: an episode opens at an event of a kind in
    `starts` for the ball (unless one is open) and closes at the next event in `ends` for the ball, or at
    the end of the trace. Without an event log, runs of `motion_state == state_name` in the timesteps."""
    evs = []
    for e in trace.get("events", []):
        k = e.get("kind", "")
        if k.startswith("physics_") and e.get("t") is not None:
            evs.append((float(e["t"]), k, e.get("payload") or {}))
    evs.sort(key=lambda x: x[0])
    out = []
    if evs:
        t_end = float(trace["timesteps"][-1].get("t", 0.0))
        open_ = {}
        for t, k, p in evs:
            for b in _balls_of(k, p):
                if b in open_ and (ends is None or k in ends) and t > open_[b]:
                    out.append((b, open_.pop(b), t))
                if k in starts and b not in open_:
                    open_[b] = t
        for b, t0 in open_.items():
            out.append((b, t0, t_end))
        out.sort(key=lambda x: (x[1], x[0]))
        return out
    # From frames, the state changed somewhere between two samples: an episode runs from the sample
    # before its first frame to the first sample after it, the narrowest span that holds both changes.
    runs = {}
    t_prev = None
    for s in trace.get("timesteps", []):
        t = float(s.get("t", 0.0))
        seen = set()
        for o in s.get("objects", []):
            b = str(o.get("ball_id"))
            seen.add(b)
            if o.get("motion_state") == state_name:
                if b not in runs:
                    runs[b] = [t if t_prev is None else t_prev, t]
                runs[b][1] = t
            elif b in runs:
                t0, t1 = runs.pop(b)
                out.append((b, t0, t))
        for b in [b for b in runs if b not in seen]:
            t0, t1 = runs.pop(b)
            out.append((b, t0, t))
        t_prev = t
    for b, (t0, t1) in runs.items():
        out.append((b, t0, t1))
    out.sort(key=lambda x: (x[1], x[0]))
    return out
