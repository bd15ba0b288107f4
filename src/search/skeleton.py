"""Skeleton detector for "{label}": marks the spans in which an object moves faster than a threshold.

A starting point for the search when the library has no detector for the label; the search changes
its constants, comparisons and, with an LLM, its logic."""

LABEL = "{label}"
SCALE = {scale}
THRESHOLD = 0.05
MIN_STEPS = 2


def _centre(o):
    if "position" in o:
        p = o["position"]
        return float(p[0]) / SCALE, float(p[1]) / SCALE
    if "x1" in o:
        return (float(o["x1"]) + float(o["x2"])) / (2.0 * SCALE), (float(o["y1"]) + float(o["y2"])) / (2.0 * SCALE)
    return float(o.get("x", 0.0)) / SCALE, float(o.get("y", 0.0)) / SCALE


def _oid(o):
    for key in ("ball_id", "object_index", "index"):
        if key in o:
            return str(o[key])
    return "?"


def find_pattern(trace):
    steps = trace.get("timesteps", [])
    out = []
    prev = {}
    runs = {}
    for i, s in enumerate(steps):
        t = float(s.get("t", i))
        for o in s.get("objects", []):
            k = _oid(o)
            x, y = _centre(o)
            moving = False
            if k in prev:
                px, py, pt = prev[k]
                dt = t - pt
                if dt > 0:
                    moving = ((x - px) ** 2 + (y - py) ** 2) ** 0.5 / dt > THRESHOLD
            prev[k] = (x, y, t)
            if moving:
                if k in runs:
                    runs[k][1] = i
                else:
                    runs[k] = [i, i]
            elif k in runs:
                a, b = runs.pop(k)
                if b - a + 1 >= MIN_STEPS:
                    out.append((k, a, b))
    for k, (a, b) in runs.items():
        if b - a + 1 >= MIN_STEPS:
            out.append((k, a, b))
    out.sort(key=lambda r: (r[1], r[0]))
    return [
        {
            "label": LABEL,
            "start_timestep": steps[a].get("index", a),
            "end_timestep": steps[b].get("index", b),
            "parameters": {"object_details": {k: {"id": k}}},
        }
        for k, a, b in out
    ]
