# annotrace `mutate` proposer: edits detector programs on their Python syntax tree. Standard library only.
#
# Started by src/search/mutate.rs as `python3 -I -S -B -c <this file>` with an empty environment, once per
# proposal. It parses and unparses code with `ast`; it never compiles, imports or runs it. Before reading
# its input it caps its own address space and CPU time, so hostile source (deep nesting, huge literals)
# costs at most a failed proposal.
#
# Input (stdin, JSON): {"parents": [code, ...], "seed": int, "max_edits": int}
# Output (stdout, JSON): {"ok": true, "code": str, "edits": [str, ...]} | {"ok": false, "error": str}
#
# Edits, chosen with random.Random(seed) (deterministic for a given seed, parents and Python version):
#   const   multiply a float literal by exp(N(0, 0.35)) (a zero becomes ±0.05), or move an int literal
#           >= 2 by ±1; literals in subscripts, range() arguments, round()'s digits and exponents are
#           left alone (changing them breaks programs rather than tuning them);
#   compare swap a comparison operator with a neighbour (< <=, > >=, < >, == !=);
#   splice  replace a top-level function of the first parent by the same-named, different function of
#           another parent (recombination; needs two parents).
import ast
import json
import math
import random
import resource
import sys


def _limit():
    try:
        resource.setrlimit(resource.RLIMIT_AS, (1 << 30, 1 << 30))
        resource.setrlimit(resource.RLIMIT_CPU, (10, 10))
    except (ValueError, OSError):
        pass


FLIPS = {
    ast.Lt: [ast.LtE, ast.Gt],
    ast.LtE: [ast.Lt, ast.GtE],
    ast.Gt: [ast.GtE, ast.Lt],
    ast.GtE: [ast.Gt, ast.LtE],
    ast.Eq: [ast.NotEq],
    ast.NotEq: [ast.Eq],
}


def _numbers(tree):
    """Numeric literals worth perturbing, in source order."""
    protected = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Subscript):
            for sub in ast.walk(node.slice):
                protected.add(id(sub))
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Name):
            if node.func.id == "range":
                for arg in node.args:
                    protected.add(id(arg))
            elif node.func.id == "round" and len(node.args) > 1:
                protected.add(id(node.args[1]))
        if isinstance(node, ast.BinOp) and isinstance(node.op, ast.Pow):
            protected.add(id(node.right))
    out = []
    for node in ast.walk(tree):
        if not isinstance(node, ast.Constant) or isinstance(node.value, bool):
            continue
        if id(node) in protected:
            continue
        if isinstance(node.value, float) and math.isfinite(node.value):
            out.append(node)
        elif isinstance(node.value, int) and abs(node.value) >= 2 and abs(node.value) < 10**9:
            out.append(node)
    out.sort(key=lambda n: (getattr(n, "lineno", 0), getattr(n, "col_offset", 0)))
    return out


def _compares(tree):
    out = [n for n in ast.walk(tree) if isinstance(n, ast.Compare)]
    out.sort(key=lambda n: (getattr(n, "lineno", 0), getattr(n, "col_offset", 0)))
    return out


def _perturb(rng, node):
    v = node.value
    if isinstance(v, float):
        if v == 0.0:
            new = rng.choice([-0.05, 0.05])
        else:
            new = v * math.exp(rng.gauss(0.0, 0.35))
            digits = max(3, 3 - int(math.floor(math.log10(abs(new)))))
            new = round(new, digits)
            if new == v:
                new = v * 1.1
        node.value = new
        return "const %r -> %r (line %d)" % (v, new, getattr(node, "lineno", 0))
    new = v + rng.choice([-1, 1])
    node.value = new
    return "const %d -> %d (line %d)" % (v, new, getattr(node, "lineno", 0))


def _flip(rng, node):
    i = rng.randrange(len(node.ops))
    old = type(node.ops[i])
    choices = FLIPS.get(old)
    if not choices:
        return None
    new = rng.choice(choices)
    node.ops[i] = new()
    return "compare %s -> %s (line %d)" % (old.__name__, new.__name__, getattr(node, "lineno", 0))


def _functions(tree):
    return {n.name: i for i, n in enumerate(tree.body) if isinstance(n, ast.FunctionDef)}


def _splice(rng, tree, others):
    mine = _functions(tree)
    options = []
    for k, other in enumerate(others):
        theirs = _functions(other)
        for name, j in theirs.items():
            if name in mine and ast.dump(other.body[j]) != ast.dump(tree.body[mine[name]]):
                options.append((name, k, j))
    if not options:
        return None
    name, k, j = rng.choice(sorted(options))
    tree.body[mine[name]] = others[k].body[j]
    return "splice %s from parent %d" % (name, k + 2)


def mutate(parents, seed, max_edits):
    rng = random.Random(seed)
    trees = []
    for i, code in enumerate(parents):
        try:
            trees.append(ast.parse(code))
        except (SyntaxError, ValueError, RecursionError, MemoryError) as e:
            if i == 0:
                raise ValueError("the first parent does not parse: %s" % e)
    if not trees:
        raise ValueError("no parent")
    original = ast.dump(trees[0])
    for _attempt in range(12):
        tree = ast.parse(ast.unparse(trees[0]))
        others = trees[1:]
        edits = []
        n = rng.randint(1, max(1, max_edits))
        for _ in range(n):
            ops = []
            if others:
                ops.append(("splice", 1.0))
            if _numbers(tree):
                ops.append(("const", 3.0))
            if _compares(tree):
                ops.append(("compare", 1.5))
            if not ops:
                break
            total = sum(w for _, w in ops)
            r = rng.random() * total
            op = ops[-1][0]
            for name, w in ops:
                if r < w:
                    op = name
                    break
                r -= w
            if op == "const":
                nums = _numbers(tree)
                edit = _perturb(rng, nums[rng.randrange(len(nums))])
            elif op == "compare":
                comps = _compares(tree)
                edit = _flip(rng, comps[rng.randrange(len(comps))])
            else:
                edit = _splice(rng, tree, others)
            if edit:
                edits.append(edit)
        if edits and ast.dump(tree) != original:
            return ast.unparse(ast.fix_missing_locations(tree)) + "\n", edits
    raise ValueError("no edit changes this program (no numeric literal, comparison or splice point)")


def main():
    _limit()
    try:
        msg = json.loads(sys.stdin.read())
        code, edits = mutate(
            [str(p) for p in msg["parents"]], int(msg["seed"]), int(msg.get("max_edits", 3))
        )
        out = {"ok": True, "code": code, "edits": edits}
    except (ValueError, KeyError, TypeError, SyntaxError, RecursionError, MemoryError) as e:
        out = {"ok": False, "error": "%s: %s" % (type(e).__name__, e)}
    sys.stdout.write(json.dumps(out))


main()
