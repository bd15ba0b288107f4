"""object removal: a click removes an eliminable block.

Grounded in `action_applied` events with `effective: true` (`eliminated_object` is the removed block);
a click that hit nothing (`effective: false`) removes nothing. Without an event log, an eliminable
object present in one frame and absent from the next was removed between them, and the pattern spans
those two frames; with events it is the step holding the removal. the objects the block was touching when it went are named as released
objects (they lose that contact).
"""


def find_pattern(trace):
    if not trace.get("timesteps"):
        return []
    idx, ts = _clock(trace)
    removals = []
    for t, p in _events(trace, ("action_applied",)):
        if p.get("effective") is True and p.get("eliminated_object") is not None and t <= ts[-1] + 1e-9:
            removals.append((t, str(p["eliminated_object"]), p))
    if not _events(trace, ("action_applied", "scheduled_action")):
        for oid, tr in _tracks(trace).items():
            k_last = tr[-1][0]
            if tr[-1][1].get("eliminable") and k_last + 1 < len(ts):
                removals.append((ts[k_last], oid, {"t_gone": ts[k_last + 1]}))
    out = []
    for t, oid, p in sorted(removals):
        s, e, a, b = _span(idx, ts, t, p.get("t_gone", t))
        a0 = a if "t_gone" in p else max(a - 1, 0)
        det = {oid: _detail(trace, a0, a0, oid, "removed block")}
        gone = _obj_at(trace, a0, oid)
        if gone is not None:
            for o in trace["timesteps"][a0].get("objects", []):
                other = str(o.get("index"))
                if other != oid and o.get("dynamic") and _gap(gone, o) <= KEEP_GAP:
                    det[other] = _detail(trace, a0, b, other, "released object")
        params = {"object_details": det, "t": round(t, 4)}
        if "x" in p and "y" in p:
            params["click"] = [p.get("x"), p.get("y")]
        if "t_scheduled" in p:
            params["t_scheduled"] = p["t_scheduled"]
        out.append({"label": "object removal", "start_timestep": s, "end_timestep": e, "parameters": params})
    return out
