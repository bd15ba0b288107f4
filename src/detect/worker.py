# annotrace detector worker: runs untrusted `find_pattern(trace)` functions for the Rust side.
#
# Started by src/detect/worker.rs as `python3 -s -S -B -c <this file>` with a scrubbed environment and
# resource limits already applied (RLIMIT_AS, RLIMIT_FSIZE=0, RLIMIT_NPROC, RLIMIT_NOFILE, RLIMIT_CORE=0,
# RLIMIT_CPU). Standard library only. Order of work, which matters:
#   1. import every module the worker will ever need (nothing may be imported after step 3);
#   2. keep the protocol pipes as private binary files and point sys.stdout/sys.stderr at bounded sinks;
#   3. lock the process down: no_new_privs, a Landlock ruleset with no rules (no file access at all, no TCP,
#      no signals or abstract sockets outside the process), then a seccomp filter (no sockets, no
#      exec/fork, no file opens, no file-system changes), each where the kernel offers it;
#   4. say "ready" (with the layers that are active) and serve requests.
#
# Protocol (see protocol.rs): frames of a 4-byte little-endian length and a payload whose first byte is the
# message type and the rest JSON. One reply per request, in order.
#   b"T" {"id", "trace", "steps"}   load a trace (the paper's dict, its timesteps apart, an object repeated
#                                   from the step before as 0), cached read-only        -> {"ok": true, "build": s}
#   b"P" <u32 n><header JSON, n bytes><LE block>  load a pooltool trace sent by columns (the same
#                                   dict, built from columns: floats travel as raw doubles; with
#                                   "lazy" in the header each step's `objects` are built only when
#                                   code first reads them, see LazyStep)             -> {"ok": true, "build": s}
#   b"E" {"ids": [...]}             evict traces                                        -> no reply
#   b"C" {"id", "code"}             check and compile a detector                        -> {"ok": true} | error
#   b"R" {"detectors", "trace", "flush"}  run each detector in turn -> one reply per detector: patterns | error
#                                   (written as each call ends, or with "flush" > 0 gathered and written
#                                   together, at the latest before the first call that starts "flush" seconds
#                                   after the last write, and at the end)
#                                   (patterns as b"M" <f64 wall><f64 cpu><u32 n><printed, n bytes UTF-8>
#                                   <marshal.dumps(out, 4)>, or as JSON when marshal refuses the value)
# Before every request and call at least cpu_seconds of CPU time remain below the soft RLIMIT_CPU (re-armed
# to twice that when fewer do), a backstop behind the Rust side's wall-clock timer.
# An error reply is {"ok": false, "error": {"category", "message", "line", "column", ...}}.
import sys

# What `-P` does on CPython 3.11+, for every interpreter (PyPy and older CPythons lack the flag): no
# entry for the working folder on the module path, so no file there can stand in for a module imported
# below. `sys` is built in, so importing it reads no file.
sys.path[:] = [p for p in sys.path if p]

import array
import ast
import bisect
import builtins as _builtins
import fcntl
import gc
import itertools
import json
import marshal
import os
import resource
import struct
import time

try:
    import ctypes
except Exception:  # no ctypes: the OS layers are reported as unavailable
    ctypes = None

CONFIG = json.loads(sys.argv[1]) if len(sys.argv) > 1 else {}
MAX_PATTERNS = int(CONFIG.get("max_patterns", 10000))
MAX_OUTPUT_BYTES = int(CONFIG.get("max_output_bytes", 4 << 20))
MAX_PRINT_BYTES = 4096
PYTHON_GUARD = bool(CONFIG.get("python_guard", True))
CPU_SECONDS = float(CONFIG.get("cpu_seconds", 0))
# Helper results shared between the detectors of a run request (see "Helper results shared" below).
SHARE_HELPERS = CONFIG.get("share_helpers", "off") in ("measured", "always")
SHARE_ALWAYS = CONFIG.get("share_helpers") == "always"  # whatever sharing a helper costs

# Larger pipes (1 MiB, Linux's default ceiling for unprivileged processes): a trace or a large reply then
# crosses in one or two writes instead of many 64 KiB rounds, each of which wakes the other side.
for _fd in (0, 1):
    try:
        fcntl.fcntl(_fd, 1031, 1 << 20)  # F_SETPIPE_SZ
    except (OSError, ValueError, AttributeError):
        pass
_IN = open(0, "rb", buffering=0, closefd=False)
_OUT = open(1, "wb", buffering=0, closefd=False)
_PACK = struct.Struct("<I")
_MARSHAL_HEAD = struct.Struct("<ddI")  # wall, cpu, length of the printed text


class _Sink:
    """Bounded text sink standing in for stdout/stderr: a detector that prints 1 GB costs time, not memory."""

    def __init__(self):
        self.parts = []
        self.size = 0

    def write(self, s):
        s = str(s)
        if self.size < MAX_PRINT_BYTES:
            self.parts.append(s[: MAX_PRINT_BYTES - self.size])
        self.size += len(s)
        return len(s)

    def flush(self):
        pass

    def take(self):
        out = "".join(self.parts)
        self.parts = []
        self.size = 0
        return out


_SINK = _Sink()
sys.stdout = _SINK
sys.stdin = None


def _read_exact(n):
    buf = bytearray()
    while len(buf) < n:
        chunk = _IN.read(n - len(buf))
        if not chunk:
            sys.exit(0)
        buf += chunk
    return bytes(buf)


_OUTBOX = []  # frames not written yet (a run request may gather several replies into one write)


def _send(payload, flush=True):
    _OUTBOX.append(_PACK.pack(len(payload)))
    _OUTBOX.append(payload)
    if flush:
        _flush()


def _flush():
    """Writes every waiting frame with one system call (more only if the pipe takes part of it)."""
    if not _OUTBOX:
        return
    data = memoryview(b"".join(_OUTBOX))
    _OUTBOX.clear()
    while data:
        data = data[_OUT.write(data):]


def _reply(obj):
    _send(json.dumps(obj, separators=(",", ":")).encode())


# ---------------------------------------------------------------------------------------------------
# Step 3: OS layers.

_SYS = {  # x86_64 syscall numbers
    "read": 0, "write": 1, "open": 2, "socket": 41, "connect": 42, "accept": 43, "sendto": 44,
    "recvfrom": 45, "sendmsg": 46, "recvmsg": 47, "shutdown": 48, "bind": 49, "listen": 50,
    "socketpair": 53, "clone": 56, "fork": 57, "vfork": 58, "execve": 59, "kill": 62, "truncate": 76,
    "getdents": 78, "chdir": 80, "rename": 82, "mkdir": 83, "rmdir": 84, "creat": 85, "link": 86,
    "unlink": 87, "symlink": 88, "chmod": 90, "fchmod": 91, "chown": 92, "fchown": 93, "lchown": 94,
    "ptrace": 101, "mknod": 133, "personality": 135, "pivot_root": 155, "chroot": 161, "mount": 165,
    "umount2": 166, "getdents64": 217, "openat": 257, "mkdirat": 258, "mknodat": 259,
    "fchownat": 260, "unlinkat": 263, "renameat": 264, "linkat": 265, "symlinkat": 266,
    "fchmodat": 268, "unshare": 272, "accept4": 288, "perf_event_open": 298, "setns": 308,
    "process_vm_readv": 310, "process_vm_writev": 311, "renameat2": 316, "memfd_create": 319,
    "bpf": 321, "execveat": 322, "userfaultfd": 323, "io_uring_setup": 425, "io_uring_enter": 426,
    "io_uring_register": 427, "open_tree": 428, "move_mount": 429, "fsopen": 430, "clone3": 435,
    "openat2": 437, "pidfd_getfd": 438,
}
_DENY = [
    "open", "openat", "openat2", "creat", "socket", "connect", "accept", "accept4", "sendto",
    "recvfrom", "sendmsg", "recvmsg", "shutdown", "bind", "listen", "socketpair", "fork", "vfork",
    "execve", "execveat", "kill", "truncate", "getdents", "getdents64", "chdir", "rename", "renameat",
    "renameat2", "mkdir", "mkdirat", "rmdir", "link", "linkat", "unlink", "unlinkat", "symlink",
    "symlinkat", "chmod", "fchmod", "fchmodat", "chown", "fchown", "lchown", "fchownat", "mknod",
    "mknodat", "ptrace", "personality", "pivot_root", "chroot", "mount", "umount2", "unshare",
    "setns", "perf_event_open", "process_vm_readv", "process_vm_writev", "memfd_create", "bpf",
    "userfaultfd", "io_uring_setup", "io_uring_enter", "io_uring_register", "open_tree",
    "move_mount", "fsopen", "pidfd_getfd",
]


def _no_new_privs(libc):
    return libc.prctl(38, 1, 0, 0, 0) == 0  # PR_SET_NO_NEW_PRIVS


def _landlock(libc):
    """A ruleset that handles every access right the kernel knows and grants none."""
    libc.syscall.restype = ctypes.c_long
    abi = libc.syscall(444, None, ctypes.c_size_t(0), ctypes.c_uint(1))  # LANDLOCK_CREATE_RULESET_VERSION
    if abi < 1:
        return "unavailable"
    fs = (1 << 13) - 1  # ABI 1: execute … make_sym
    if abi >= 2:
        fs |= 1 << 13  # refer
    if abi >= 3:
        fs |= 1 << 14  # truncate
    if abi >= 5:
        fs |= 1 << 15  # ioctl_dev
    net = 3 if abi >= 4 else 0  # bind_tcp | connect_tcp
    scoped = 3 if abi >= 6 else 0  # abstract unix sockets | signals

    class Attr(ctypes.Structure):
        _fields_ = [("fs", ctypes.c_uint64), ("net", ctypes.c_uint64), ("scoped", ctypes.c_uint64)]

    attr = Attr(fs, net, scoped)
    size = 8 if abi < 4 else (16 if abi < 6 else 24)
    fd = libc.syscall(444, ctypes.byref(attr), ctypes.c_size_t(size), ctypes.c_uint(0))
    if fd < 0:
        return "unavailable"
    ok = libc.syscall(446, ctypes.c_int(fd), ctypes.c_uint(0)) == 0  # landlock_restrict_self
    libc.close(fd)
    return "abi%d" % abi if ok else "unavailable"


def _seccomp(libc):
    """A BPF filter: x86_64 only; denied syscalls fail with EPERM (clone3 with ENOSYS, so that glibc falls
    back to clone); clone is allowed only for threads (CLONE_THREAD)."""
    if struct.calcsize("P") != 8 or _machine() != "x86_64":
        return "unavailable"

    class Insn(ctypes.Structure):
        _fields_ = [("code", ctypes.c_ushort), ("jt", ctypes.c_ubyte), ("jf", ctypes.c_ubyte),
                    ("k", ctypes.c_uint32)]

    class Prog(ctypes.Structure):
        _fields_ = [("len", ctypes.c_ushort), ("filter", ctypes.POINTER(Insn))]

    LD, JEQ, JSET, RET = 0x20, 0x15, 0x45, 0x06
    ALLOW, KILL = 0x7FFF0000, 0x80000000
    EPERM, ENOSYS = 0x00050000 | 1, 0x00050000 | 38
    denied = sorted(set(_SYS[n] for n in _DENY))
    prog = [
        (LD, 0, 0, 4),  # arch
        (JEQ, 1, 0, 0xC000003E),  # AUDIT_ARCH_X86_64
        (RET, 0, 0, KILL),
        (LD, 0, 0, 0),  # syscall number
        (0x35, 0, 1, 0x40000000),  # jge: x32 ABI -> deny
        (RET, 0, 0, EPERM),
        (JEQ, 0, 1, _SYS["clone3"]),
        (RET, 0, 0, ENOSYS),
        (JEQ, 0, 4, _SYS["clone"]),  # not clone: on to the deny list
        (LD, 0, 0, 16),  # clone flags (low 32 bits of args[0])
        (JSET, 1, 0, 0x00010000),  # CLONE_THREAD
        (RET, 0, 0, EPERM),
        (RET, 0, 0, ALLOW),
        (LD, 0, 0, 0),
    ]
    for nr in denied:
        prog.append((JEQ, 0, 1, nr))
        prog.append((RET, 0, 0, EPERM))
    prog.append((RET, 0, 0, ALLOW))
    arr = (Insn * len(prog))(*[Insn(*i) for i in prog])
    fprog = Prog(len(prog), arr)
    ok = libc.prctl(22, 2, ctypes.byref(fprog), 0, 0) == 0  # PR_SET_SECCOMP, SECCOMP_MODE_FILTER
    return "filter" if ok else "unavailable"


def _machine():
    try:
        return os.uname().machine
    except Exception:
        return ""


def _lock_down():
    layers = {"no_new_privs": False, "landlock": "unavailable", "seccomp": "unavailable"}
    if not CONFIG.get("os_layers", True) or ctypes is None:
        return layers
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        layers["no_new_privs"] = _no_new_privs(libc)
        if layers["no_new_privs"]:
            if CONFIG.get("landlock", True):
                layers["landlock"] = _landlock(libc)
            if CONFIG.get("seccomp", True):
                layers["seccomp"] = _seccomp(libc)
    except Exception as e:  # report, never crash: the Rust side decides whether that is acceptable
        layers["error"] = repr(e)
    return layers


# ---------------------------------------------------------------------------------------------------
# The Python layer: checked source, reduced builtins, read-only traces.

FORBIDDEN_NAMES = {
    "eval", "exec", "compile", "open", "input", "breakpoint", "globals", "locals", "vars", "dir",
    "getattr", "setattr", "delattr", "hasattr", "type", "super", "object", "memoryview", "help",
    "exit", "quit", "classmethod", "staticmethod", "property", "bytearray", "id", "__import__",
}
FORBIDDEN_ATTRS = {
    "gi_frame", "gi_code", "gi_yieldfrom", "cr_frame", "cr_code", "cr_await", "ag_frame", "ag_code",
    "ag_await", "f_back", "f_globals", "f_locals", "f_builtins", "f_code", "tb_frame", "tb_next",
    "co_code", "co_consts", "mro", "format_map",
}


class ForbiddenError(Exception):
    def __init__(self, what, node):
        Exception.__init__(self, what)
        self.what = what
        self.line = getattr(node, "lineno", None)
        self.column = getattr(node, "col_offset", -1) + 1 or None


def check_source(tree):
    """Refuses what the Python layer forbids (ForbiddenError) and returns, from the same one walk over
    the tree, what compiling the detector needs to know: whether it defines `find_pattern`; the plain
    names it uses; whether its module-level bindings and its functions are fixed once the module has
    run (no `global` statement, no attribute stored or deleted: see "Helper results shared"); and each
    `except` clause's line with the names it catches (None unless they are plain names)."""
    has_find_pattern = False
    names = set()
    fixed = True
    handlers = []
    Name, Attribute, Load = ast.Name, ast.Attribute, ast.Load
    for node in ast.walk(tree):
        t = type(node)
        if t is Name:
            i = node.id
            if i.startswith("__") or i in FORBIDDEN_NAMES:
                raise ForbiddenError("the name `%s` is not allowed" % i, node)
            names.add(i)
        elif t is Attribute:
            a = node.attr
            if a.startswith("_") or a in FORBIDDEN_ATTRS:
                raise ForbiddenError("attribute access `.%s` is not allowed" % a, node)
            if type(node.ctx) is not Load:
                fixed = False
        elif t is ast.Import or t is ast.ImportFrom:
            raise ForbiddenError("import statements are not allowed (detectors may use only the trace)", node)
        elif t is ast.ClassDef:
            raise ForbiddenError("class definitions are not allowed", node)
        elif t is ast.FunctionDef or t is ast.AsyncFunctionDef:
            if node.name == "find_pattern":
                has_find_pattern = True
        elif t is ast.Global:
            for n in node.names:
                if n.startswith("__"):
                    raise ForbiddenError("the name `%s` is not allowed" % n, node)
            fixed = False
        elif t is ast.ExceptHandler:
            caught = node.type.elts if type(node.type) is ast.Tuple else (node.type,)
            handlers.append((node.lineno, tuple(c.id for c in caught) if all(type(c) is Name for c in caught)
                             else None))
    return has_find_pattern, names, fixed, handlers


_TYPE_TESTS = ("isinstance", "issubclass")


def reads_dict_unbound(tree):
    """Whether the code may hold the type `dict` itself, and so call its methods unbound on a step
    (`dict.get(step, "objects")`, `dict.keys(step)`): those read a dict's storage directly and would
    not see a LazyStep's objects. The name `dict` is the only way to the type (`type`, `__class__`,
    `getattr` and `vars` are refused), so this is true unless every use of the name is a call
    (`dict(x)`) or the class argument of `isinstance` / `issubclass` (alone or in a tuple) while
    neither of those names is bound anywhere in the code. Conservative: any other mention counts."""
    rebound = False
    for node in ast.walk(tree):
        if isinstance(node, ast.Constant):
            continue
        for field, value in ast.iter_fields(node):
            if field == "id" and isinstance(node, ast.Name) and isinstance(node.ctx, ast.Load):
                continue
            for v in value if isinstance(value, list) else (value,):
                if isinstance(v, str) and v in _TYPE_TESTS:
                    rebound = True
    allowed = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Name):
            if node.func.id == "dict":
                allowed.add(id(node.func))
            elif node.func.id in _TYPE_TESTS and not rebound and len(node.args) == 2:
                cls = node.args[1]
                for c in cls.elts if isinstance(cls, ast.Tuple) else (cls,):
                    if isinstance(c, ast.Name) and c.id == "dict":
                        allowed.add(id(c))
    return any(isinstance(n, ast.Name) and n.id == "dict" and id(n) not in allowed for n in ast.walk(tree))


def _print(*args, sep=" ", end="\n", **_kw):
    _SINK.write(sep.join(str(a) for a in args) + end)


_SAFE = [
    "abs", "all", "any", "ascii", "bin", "bool", "callable", "chr", "complex", "dict", "divmod",
    "enumerate", "filter", "float", "format", "frozenset", "hash", "hex", "int", "isinstance",
    "issubclass", "iter", "len", "list", "map", "max", "min", "next", "oct", "ord", "pow", "range",
    "repr", "reversed", "round", "set", "slice", "sorted", "str", "sum", "tuple", "zip", "bytes",
    "ArithmeticError", "AssertionError", "AttributeError", "Exception", "IndexError", "KeyError",
    "LookupError", "NameError", "NotImplementedError", "OverflowError", "RuntimeError",
    "StopIteration", "TypeError", "ValueError", "ZeroDivisionError", "True", "False", "None",
]
SAFE_BUILTINS = {n: getattr(_builtins, n) for n in _SAFE if hasattr(_builtins, n)}
SAFE_BUILTINS["print"] = _print
if not PYTHON_GUARD:
    # Tests of the OS layers only: the detector sees the real builtins, so only the OS stops it.
    SAFE_BUILTINS = _builtins.__dict__


class FrozenDict(dict):
    """A trace dict detectors can read but not change (so one detector cannot corrupt the cached trace
    for the next); `.copy()` and `dict(x)` give ordinary dicts."""

    # Set only while a LazyStep's objects are not built (its builder and step position); every other
    # FrozenDict leaves it empty. The same layout in both classes lets a LazyStep become a FrozenDict.
    __slots__ = ("_lazy",)

    def _read_only(self, *a, **k):
        raise TypeError("the trace is read-only; copy it first (dict(x), list(x))")

    __setitem__ = __delitem__ = pop = popitem = clear = update = setdefault = __ior__ = _read_only


_dict_get = dict.get
_dict_len = dict.__len__
_dict_contains = dict.__contains__
_dict_set = dict.__setitem__
_dict_del = dict.__delitem__
_dict_update = dict.update


class LazyStep(FrozenDict):
    """A pooltool timestep whose `objects` are built when code first reads them (the built-in detectors
    read the objects of under half the steps; a reward program's few detectors, far fewer).

    Until then the dict holds `index`, `t` and the step's extra fields, and the methods below answer
    as the full step would: a subscript of "objects" (through `__missing__`), `get("objects")` and
    every method that shows all keys or values build the objects first, insert them where the eager
    build puts them (after `t`), and turn the instance into a plain FrozenDict, so from then on every
    read runs at C speed and the step is exactly the eager build's. `len` and `in` answer without
    building. Reads of present keys (`step["t"]`) never enter Python code. What this class cannot
    intercept, dict's methods called unbound on the step (`dict.get(step, "objects")`), cannot be
    reached by a detector that does not name the type `dict` (see `reads_dict_unbound`), and one
    that does gets every step built before its call. Its name in error messages is "FrozenDict", as
    for the eager build."""

    __slots__ = ()

    def _realise(self):
        builder, s = self._lazy
        objs = builder.objects(s)
        if _dict_len(self) == 2:
            _dict_set(self, "objects", objs)
        else:  # extra step fields come after `objects`, as in the eager build
            rest = list(dict.items(self))[2:]
            for key, _v in rest:
                _dict_del(self, key)
            _dict_set(self, "objects", objs)
            for key, v in rest:
                _dict_set(self, key, v)
        del self._lazy
        self.__class__ = FrozenDict
        return objs

    def __missing__(self, key):
        if key == "objects":
            return self._realise()
        raise KeyError(key)

    def get(self, key, default=None, /):
        if key == "objects":
            return self._realise()
        return _dict_get(self, key, default)

    def __contains__(self, key):
        return key == "objects" or _dict_contains(self, key)

    def __len__(self):
        return _dict_len(self) + 1

    def keys(self, *a, **k):
        self._realise()
        return dict.keys(self, *a, **k)

    def values(self, *a, **k):
        self._realise()
        return dict.values(self, *a, **k)

    def items(self, *a, **k):
        self._realise()
        return dict.items(self, *a, **k)

    def copy(self, *a, **k):
        self._realise()
        return dict.copy(self, *a, **k)

    @classmethod
    def fromkeys(cls, *a, **k):
        return FrozenDict.fromkeys(*a, **k)

    def __iter__(self):
        self._realise()
        return dict.__iter__(self)

    def __reversed__(self):
        self._realise()
        return dict.__reversed__(self)

    def __repr__(self):
        self._realise()
        return dict.__repr__(self)

    # dict's comparison reads both operands' storage: build the other operand's objects too.
    def __eq__(self, other):
        self._realise()
        if type(other) is LazyStep:
            other._realise()
        return dict.__eq__(self, other)

    def __ne__(self, other):
        self._realise()
        if type(other) is LazyStep:
            other._realise()
        return dict.__ne__(self, other)

    if hasattr(dict, "__or__"):  # Python 3.9+
        def __or__(self, other):
            self._realise()
            if type(other) is LazyStep:
                other._realise()
            return dict.__or__(self, other)

        def __ror__(self, other):  # dict.__ror__ as CPython has it (PyPy 3.9's dict has none)
            self._realise()
            if not isinstance(other, dict):
                return NotImplemented
            return dict.__or__(other, self)


LazyStep.__name__ = LazyStep.__qualname__ = "FrozenDict"


def _tuples(v):
    """A JSON list as a tuple, and every list inside it through lists (dicts inside were frozen by the
    JSON hook already), so no list of a cached trace can be appended to or changed in place."""
    if list in map(type, v):
        return tuple([_tuples(x) if type(x) is list else x for x in v])
    return tuple(v)


def _freeze(d):
    for k, v in d.items():
        if type(v) is list:
            dict.__setitem__(d, k, _tuples(v))
    return FrozenDict(d)


def _private_copy(v, memo):
    """A copy of a cached trace's read-only dicts and the tuples holding them, for a detector that may
    call dict's methods unbound (`dict.update(step, ...)` writes past FrozenDict's refusals): what it
    changes is its own copy, never the trace the next detector reads. Shared values stay shared in the
    copy (`memo`, by id), so a ball dict repeated in consecutive steps is still one object; strings,
    numbers and tuples of them are immutable and are not copied."""
    t = type(v)
    if t is FrozenDict or t is tuple:
        c = memo.get(id(v))
        if c is None:
            if t is tuple:
                items = [_private_copy(x, memo) for x in v]
                c = v if all(a is b for a, b in zip(items, v)) else tuple(items)
            else:
                c = FrozenDict([(k, _private_copy(x, memo)) for k, x in dict.items(v)])
            memo[id(v)] = c
        return c
    return v


# ---------------------------------------------------------------------------------------------------
# Helper results shared between the detectors of one run request (config `share_helpers`: "measured"
# shares while it pays, "always" whatever it costs; sandbox.rs `HelperSharing`).
#
# The detectors of a library carry the same prelude helpers (`_contacts(trace)`, `_kin(trace)`,
# `_clock(trace)`), each compiled into its own namespace, and call them on the same cached trace. A
# helper is shared when its result can depend on nothing but its arguments, so that every detector
# computing it would get an equal value:
#   * it is a module-level `def` (no decorator) whose first parameter is named `trace`, not
#     `find_pattern`, and not (directly or through other helpers) recursive;
#   * it and the functions it calls catch no exception that a call's depth or the worker's memory
#     can raise (only builtin ones such as KeyError, TypeError, ValueError: `_CATCHABLE`), so what
#     it returns cannot depend on where it is called from;
#   * the detector's code has no `global` statement and stores or deletes no attribute anywhere, so
#     its module-level bindings and its functions are fixed once the module has run;
#   * every module-level name the helper reads (with the helpers it calls, transitively) is bound to
#     a constant (numbers, strings, bytes, None, tuples and frozensets of them, a builtin other than
#     `print`) or to another function meeting the same conditions, or is a builtin other than `print`;
#     its default values are constants too.
# Its fingerprint numbers the helper's code object with the names and values it reads (functions by
# their own fingerprints): two detectors share a result only when all of these are equal.
# A call is answered from the cache only when its first argument is the request's cached trace
# itself (read-only, and the same object for every detector of the request) and every other argument
# is a constant; the cached value is a private copy taken when the result was computed, and every
# caller gets its own copy of it (lists and dicts copied, sharing inside the value kept; the trace's
# read-only dicts, constants, and tuples that hold nothing else reused). A value holding anything else
# (a set, whose iteration order a copy need not keep; a function; a generator) is not cached. Only
# helpers that two or more detectors of the request reach are cached, and the last of them takes the
# cached value itself; in "measured" mode a helper cheap to compute or dear to copy is called directly
# again after its first results, as is one a detector keeps calling in ways that cannot be shared. Detectors that may call dict's methods unbound (they read a private copy of
# the trace) share nothing. What is shared is never computed again, so `cpu` of a call counts the
# helpers it computed, not those it was handed.

_FunctionType = type(_print)
_F64 = struct.Struct("<d")
_ATOMS = frozenset((int, float, complex, str, bytes, bool, type(None)))
# Values a copy reuses: constants, and the trace's read-only dicts. Detector code can make no
# FrozenDict but an empty one (`fromkeys` stores through the refusing `__setitem__`), so every one it
# can hold is the trace's, read-only all the way down (dicts frozen, lists made tuples at load).
_AS_IS = _ATOMS | {FrozenDict, LazyStep}
_TUPLE = {tuple}
_chain = itertools.chain.from_iterable
_BUILTIN_VALUES = {id(v): n for n, v in SAFE_BUILTINS.items() if n != "print"}
_SHARED = {}  # fingerprint -> {argument key: (cached value, ids of its lists copied by a slice)}
_SHARE_LEFT = {}  # fingerprint -> detectors of the request yet to run that reach it
_SHARE_TRACE = [None]  # the cached trace while a sharing detector runs, else None
_FINGERPRINTS = {}  # a function's code and what it reads -> its fingerprint, a number
_SHARE_COST = {}  # fingerprint -> [results computed for sharing, their CPU s, the CPU s of copying them]
_UNSHARED = set()  # fingerprints found not worth sharing: cheap to compute, dear to copy, or uncopyable
_SHARE_TRIAL = 3  # results computed before a helper's cost is judged
_SHARE_MIN_S = 20e-6  # a helper computed in less (on average) is called, not shared
_SHARE_MAX_COPY = 0.8  # nor one whose results take more than this share of its time to copy
_SHARE_UNKEYED = 100  # calls a detector makes that cannot be shared before it calls the helper directly


class _NotShared(Exception):
    pass


def _constant(v):
    """Whether `v` is a constant: a value `_key` can key."""
    try:
        _key(v)
    except _NotShared:
        return False
    return True


def _code_names(code, out):
    out.update(code.co_names)
    for c in code.co_consts:
        if type(c) is type(code):
            _code_names(c, out)
    return out


# Exceptions a shared helper may catch: none that a call's depth or the worker's memory can raise
# (RecursionError, MemoryError and their bases), so that what it returns cannot depend on who calls it.
_CATCHABLE = frozenset((
    "ArithmeticError", "AssertionError", "AttributeError", "IndexError", "KeyError", "LookupError",
    "NameError", "NotImplementedError", "OverflowError", "StopIteration", "TypeError", "ValueError",
    "ZeroDivisionError",
))


def _fingerprint(fn, ns, memo, safe):
    """The fingerprint of a shareable function of `ns` (a number, equal for two functions only when
    their code and everything they read are), or None (see above). `safe`: the (name, first line) of
    the module-level `def`s whose handlers catch only `_CATCHABLE`."""
    if fn in memo:
        return memo[fn]  # None while it is being walked: recursion is not shared
    memo[fn] = None
    if fn.__globals__ is not ns or fn.__closure__ is not None \
            or (fn.__code__.co_name, fn.__code__.co_firstlineno) not in safe:
        return None
    defaults = (fn.__defaults__ or ()) + tuple(sorted((fn.__kwdefaults__ or {}).items()))
    if not _constant(defaults):
        return None
    # Code objects compare by value (bytecode, constants by type and value, names, line table).
    parts = [fn.__code__, _key(defaults)]
    for name in sorted(_code_names(fn.__code__, set())):
        if name in ns:
            v = ns[name]
            if type(v) is _FunctionType:
                sub = _fingerprint(v, ns, memo, safe)
                if sub is None:
                    return None
                parts.append((name, sub))
            elif _constant(v):
                parts.append((name, _key(v)))
            else:
                return None
        elif name == "print":
            return None
    fp = _FINGERPRINTS.setdefault(tuple(parts), len(_FINGERPRINTS))
    memo[fn] = fp
    return fp


def share_helpers(tree, ns, handlers):
    """Replaces each shareable helper of a compiled detector's namespace by a sharing wrapper; returns
    their fingerprints. `handlers`: the `except` clauses `check_source` found. Only for checked code
    whose bindings are fixed (`check_source`)."""
    # The lines of `except` clauses that may catch more than `_CATCHABLE` (builtins not rebound).
    wide = [line for line, caught in handlers
            if caught is None or any(c not in _CATCHABLE or c in ns for c in caught)]
    found = []
    memo = {}
    safe = {(node.name, node.lineno) for node in tree.body
            if type(node) is ast.FunctionDef and not node.decorator_list
            and not any(node.lineno <= line <= node.end_lineno for line in wide)}
    for node in tree.body:
        if not isinstance(node, ast.FunctionDef) or node.decorator_list or node.name == "find_pattern":
            continue
        params = node.args.posonlyargs + node.args.args
        if not params or params[0].arg != "trace":
            continue
        fn = ns.get(node.name)
        if type(fn) is not _FunctionType or fn.__code__.co_firstlineno != node.lineno \
                or fn.__code__.co_name != node.name:
            continue  # bound to something else by the end of the module
        fp = _fingerprint(fn, ns, memo, safe)
        if fp is not None and fp not in _UNSHARED:
            found.append((node.name, fn, fp))
    for name, fn, fp in found:
        ns[name] = _sharing(fn, fp, ns, name)
    return tuple(fp for _, _, fp in found)


def _key(v):
    """A key equal for two constants only when they are the same value of the same type (-0.0 and 0.0
    apart; a builtin by its name); raises _NotShared for anything else."""
    t = type(v)
    if t is float:
        return (t, _F64.pack(v))  # the bits: -0.0 and 0.0 apart, NaNs by sign and payload
    if t is complex:
        return (t, repr(v))
    if t in _ATOMS:
        return (t, v)
    if t is tuple or t is frozenset:
        return (t, tuple(map(_key, v)))
    name = _BUILTIN_VALUES.get(id(v))
    if name is not None and SAFE_BUILTINS.get(name) is v:
        return ("builtin", name)
    raise _NotShared


def _sharing(fn, fp, ns, name):
    unshareable = [0]  # calls this detector made that could not be shared

    def direct(args, kwargs):
        # A detector that keeps calling the helper on something other than the trace, or with
        # arguments that are not constants, calls it directly from then on.
        unshareable[0] += 1
        if unshareable[0] >= _SHARE_UNKEYED:
            ns[name] = fn
        return fn(*args, **kwargs)

    def call(*args, **kwargs):
        trace = _SHARE_TRACE[0]
        if trace is None or not args or args[0] is not trace:
            return direct(args, kwargs)
        left = _SHARE_LEFT.get(fp, 0)
        cache = _SHARED.get(fp)
        if left < 2 and not cache:
            return fn(*args, **kwargs)  # no other detector of the request reaches it, or none is left
        try:
            key = (tuple(map(_key, args[1:])), tuple((k, _key(v)) for k, v in kwargs.items()))
        except _NotShared:
            return direct(args, kwargs)
        if cache is not None and key in cache:
            if left == 1:
                return cache.pop(key)[0]  # the last detector that reaches it: the copy itself
            snap, flat = cache[key]
            return _copy(snap, {}, flat)
        if left == 1:
            return fn(*args, **kwargs)
        c0 = _cpu_clock()
        value = fn(*args, **kwargs)
        c1 = _cpu_clock()
        flat = set()
        try:
            snap = _copy(value, {}, None, flat)
        except (_NotShared, RecursionError):
            snap = _NotShared
        c2 = _cpu_clock()
        st = _SHARE_COST.get(fp)
        if st is None:
            st = _SHARE_COST[fp] = [0, 0.0, 0.0]
        st[0] += 1
        st[1] += c1 - c0
        st[2] += c2 - c1
        if snap is _NotShared or (not SHARE_ALWAYS and st[0] >= _SHARE_TRIAL
                                  and (st[1] < st[0] * _SHARE_MIN_S or st[2] > _SHARE_MAX_COPY * st[1])):
            # Not worth it (or not possible): this detector and every one compiled later call the
            # helper itself.
            _UNSHARED.add(fp)
            ns[name] = fn
            return value
        _SHARED.setdefault(fp, {})[key] = (snap, flat)
        return value

    call.__name__ = call.__qualname__ = fn.__name__
    return call


def _copy(v, memo, known=None, found=None):
    """A copy of a helper's result that no other caller's changes can reach (see above); raises
    _NotShared for a value that cannot be copied exactly. A list that holds only constants and
    read-only dicts, or tuples of only those, is copied by one slice after type tests at C speed;
    `found` (when a cached value is taken) collects the ids of such lists in the copy, and `known`
    (when a cached value is copied) names them, so they are sliced without the tests: a cached value
    is never changed while it is cached."""
    t = type(v)
    if t in _AS_IS:
        return v
    if t is list or t is dict:
        c = memo.get(id(v))
        if c is not None:
            return c
        if t is list:
            c = []
            memo[id(v)] = c
            if known is not None and id(v) in known:
                c.extend(v)
            else:
                types = set(map(type, v))
                if types <= _AS_IS or (types == _TUPLE and set(map(type, _chain(v))) <= _AS_IS):
                    c.extend(v)
                    if found is not None:
                        found.add(id(c))
                else:
                    c.extend([x if type(x) in _AS_IS else _copy(x, memo, known, found) for x in v])
        else:
            c = {}
            memo[id(v)] = c
            for k, x in v.items():
                if type(k) not in _ATOMS and not _constant(k):
                    raise _NotShared
                c[k] = x if type(x) in _AS_IS else _copy(x, memo, known, found)
        return c
    if t is tuple:
        for x in v:
            if type(x) not in _AS_IS:
                items = [x if type(x) in _AS_IS else _copy(x, memo, known, found) for x in v]
                return v if all(a is b for a, b in zip(items, v)) else tuple(items)
        return v
    if t is frozenset and _constant(v):
        return v
    raise _NotShared


def share_begin(detector_ids):
    """Before a run request: which helpers its detectors reach, and how many of them."""
    share_end()
    for i in detector_ids:
        d = DETECTORS.get(i)
        if d is not None:
            for fp in d[2]:
                _SHARE_LEFT[fp] = _SHARE_LEFT.get(fp, 0) + 1


def share_after(fingerprints):
    """After a sharing detector's call: one detector fewer left for each helper it reaches; a
    helper's cached values go when none is."""
    for fp in fingerprints:
        left = _SHARE_LEFT.get(fp, 0) - 1
        if left > 0:
            _SHARE_LEFT[fp] = left
        else:
            _SHARE_LEFT.pop(fp, None)
            _SHARED.pop(fp, None)


def share_end():
    _SHARED.clear()
    _SHARE_LEFT.clear()
    _SHARE_TRACE[0] = None


TRACES = {}
DETECTORS = {}
_GC_FREEZE = getattr(gc, "freeze", None)


_U32 = "I" if array.array("I").itemsize == 4 else "L"
_VEC3 = struct.Struct("<3d")
class _PoolStates:
    """One pooltool trace's ball states and step rows as `pool_columns` (protocol.rs) sends them.
    When a step's objects are first read, builds the states new in that step (one contiguous range,
    in one pass), those new in the steps where its other balls (which have not moved since) took
    their state, and its tuple. Each state's read-only dict is built once, so a ball unchanged
    between steps is the same dict in both, and steps that share a row share the tuple, as in the
    eager build, whichever step is read first. Holds the load frame; never reachable from detector
    code. Also builds a whole trace in one pass (`_rows(0, n)`) when it is not loaded lazily."""

    __slots__ = ("frame", "at", "radii", "protos", "proto", "firsts", "starts", "rows", "balls",
                 "built", "tuples")

    def objects(self, s):
        objs = self.tuples.get(self.starts[s])
        if objs is None:
            self._rows(s, s + 1)
            objs = self.tuples[self.starts[s]]
        return objs

    def _states(self, s0, s1):
        """The states new in steps s0..s1 (none of them built yet)."""
        self.built[s0:s1] = b"\x01" * (s1 - s0)
        qa, qb = self.firsts[s0], self.firsts[s1]
        if qa == qb:
            return
        vecs = _VEC3.iter_unpack(self.frame[self.at + 72 * qa:self.at + 72 * qb])
        fd = FrozenDict
        self.balls[qa:qb] = [
            fd(kind=kind, ball_id=bid, position=p, velocity=v, angular_velocity=w,
               motion_state_code=code, motion_state=state, radius=r)
            for (bid, kind, code, state), p, v, w, r
            in zip(map(self.protos.__getitem__, self.proto[qa:qb]), vecs, vecs, vecs,
                   self.radii[qa:qb])]

    def _rows(self, s0, s1):
        """The object tuples of steps s0..s1."""
        built = self.built
        if not any(built[s0:s1]):
            self._states(s0, s1)
        else:
            for s in range(s0, s1):
                if not built[s]:
                    self._states(s, s + 1)
        balls, rows, tuples, starts = self.balls, self.rows, self.tuples, self.starts
        # States new before s0 are those that balls which did not move hold; every one a row of
        # these steps holds is in the first row (a slot that changes takes a state new in them).
        qa = self.firsts[s0]
        o = starts[s0]
        for q in rows[o + 1:o + 1 + rows[o]]:
            if q < qa and balls[q] is None:
                t = bisect.bisect_right(self.firsts, q) - 1  # the step where state q is new
                self._states(t, t + 1)
        get = balls.__getitem__
        for o in set(starts[s0:s1]):
            if o not in tuples:
                tuples[o] = tuple(map(get, rows[o + 1:o + 1 + rows[o]]))


def load_pool_columns(frame):
    """Rebuilds a pooltool trace dict, identical to the JSON path's, from its columns (protocol.rs
    `pool_columns` describes the layout). With `lazy` in the header (the Rust side sends it for
    runs of a few detectors) the steps are LazyStep dicts holding `index` and `t` (and any extra
    fields), whose `objects` are built when code first reads them (`_PoolStates`); else every step is
    built now."""
    (hlen,) = _PACK.unpack(frame[1:5])
    head = json.loads(frame[5:5 + hlen], object_hook=_freeze)
    indices, n_new, n_words = head["index"], head["states"], head["words"]
    n_steps = len(indices)
    view = memoryview(frame)
    at = 5 + hlen
    times = array.array("d")
    times.frombytes(view[at:at + 8 * n_steps])
    at += 8 * n_steps
    b = _PoolStates()
    b.frame = view
    b.at = at
    at += 72 * n_new
    b.radii = array.array("d")
    b.radii.frombytes(view[at:at + 8 * n_new])
    at += 8 * n_new
    ints = array.array(_U32)  # proto, firsts, starts, rows
    ints.frombytes(view[at:at + 4 * (n_new + (n_steps + 1) + n_steps + n_words)])
    if sys.byteorder != "little":
        times.byteswap()
        b.radii.byteswap()
        ints.byteswap()
    b.proto = ints[:n_new]
    b.firsts = ints[n_new:n_new + n_steps + 1]
    b.starts = ints[n_new + n_steps + 1:n_new + 2 * n_steps + 1]
    b.rows = ints[n_new + 2 * n_steps + 1:]
    b.protos = head["protos"]
    b.balls = [None] * n_new
    b.built = bytearray(n_steps)
    b.tuples = {}
    extras = head.get("step_extra") or ()
    if not head.get("lazy"):
        # Built whole (a run of many detectors reads most of the states: built in one pass, they
        # cost less than one step at a time).
        if n_steps:
            b._rows(0, n_steps)
        tuples, starts, fd = b.tuples, b.starts, FrozenDict
        steps = [fd(index=ix, t=t, objects=tuples[starts[s]])
                 for s, (ix, t) in enumerate(zip(indices, times.tolist()))]
        for step, extra in zip(steps, extras):
            if extra:
                _dict_update(step, extra)
    else:
        ls = LazyStep
        steps = []
        append = steps.append
        for s, (ix, t) in enumerate(zip(indices, times.tolist())):
            step = ls(index=ix, t=t)
            step._lazy = (b, s)
            append(step)
        for step, extra in zip(steps, extras):
            if extra:
                _dict_update(step, extra)
    shell = head["trace"]
    return head["id"], FrozenDict((key, tuple(steps) if key == "timesteps" else v) for key, v in shell.items())


def realise_all(trace):
    """Builds the objects of every step of a trace that are not built yet."""
    for step in _dict_get(trace, "timesteps", ()):
        if type(step) is LazyStep:
            step._realise()


def load_steps(frame):
    """Rebuilds a trace sent as JSON: the trace without its timesteps, then the timesteps, where an
    object written as 0 repeats the previous step's object in the same slot (that read-only dict is
    reused)."""
    msg = json.loads(frame[1:], object_hook=_freeze)
    steps = msg["steps"]
    prev = ()
    for step in steps:
        objs = step["objects"]
        if 0 in objs:
            objs = tuple(prev[j] if type(o) is int else o for j, o in enumerate(objs))
            dict.__setitem__(step, "objects", objs)
        prev = objs
    shell = msg["trace"]
    return msg["id"], FrozenDict((key, steps if key == "timesteps" else v) for key, v in shell.items())


def _error(category, message, line=None, column=None, **extra):
    e = {"category": category, "message": message}
    if line is not None:
        e["line"] = line
    if column is not None:
        e["column"] = column
    e.update(extra)
    return {"ok": False, "error": e}


def _tb_line(tb):
    """The innermost line of the traceback that lies in detector code."""
    line = None
    while tb is not None:
        if tb.tb_frame.f_code.co_filename == "<detector>":
            line = tb.tb_lineno
        tb = tb.tb_next
    return line


_CPU = {"soft": None, "used": 0.0}  # the soft RLIMIT_CPU last set, and the CPU time at the last call's end

# The worker's CPU clock: the CPU time of its one thread. Not `time.process_time()`: once RLIMIT_CPU is
# set, Linux keeps the process-wide CPU clock only at the scheduler tick's granularity (measured: a
# 0.4 ms loop read as 0.0 ms in most calls, 1.4–4 ms in a few), which made `detector_calls.cpu_s` a
# fraction of the true time. The thread clock stays exact, and a worker has no other thread.
_cpu_clock = time.thread_time


def _set_cpu_limit(seconds, used=None):
    """Keeps the soft RLIMIT_CPU at least `seconds` (plus one) above the CPU used so far, so the kernel
    ends a call that overruns (SIGXCPU). Re-armed to twice that only when less remains: one system call
    every few seconds of CPU instead of three per call (each costs microseconds on a virtual machine).
    `used` is the CPU time already known (the end of the previous call), else it is read."""
    if not seconds:
        return
    if used is None:
        used = _cpu_clock()
    soft = _CPU["soft"]
    if soft is not None and soft - used >= seconds + 1:
        return
    want = int(used + 2 * seconds) + 1
    if _CPU_HARD != resource.RLIM_INFINITY:
        want = min(want, _CPU_HARD)
    try:
        resource.setrlimit(resource.RLIMIT_CPU, (want, _CPU_HARD))
        _CPU["soft"] = want
    except (ValueError, OSError):
        pass


_CPU_HARD = resource.getrlimit(resource.RLIMIT_CPU)[1]


def compile_detector(msg):
    code = msg.get("code", "")
    try:
        tree = ast.parse(code, "<detector>")
    except SyntaxError as e:
        return _error("syntax", e.msg, e.lineno, e.offset)
    except (ValueError, RecursionError, MemoryError) as e:
        return _error("syntax", str(e) or type(e).__name__)
    names, fixed, handlers = (), False, ()
    if PYTHON_GUARD:
        try:
            found, names, fixed, handlers = check_source(tree)
        except ForbiddenError as e:
            return _error("forbidden", e.what, e.line, e.column)
        if not found:
            return _error("no_find_pattern", "the code defines no function `find_pattern(trace)`")
    try:
        compiled = compile(tree, "<detector>", "exec")
    except (SyntaxError, ValueError, RecursionError) as e:
        return _error("syntax", str(e), getattr(e, "lineno", None), getattr(e, "offset", None))
    ns = {"__builtins__": SAFE_BUILTINS, "__name__": "detector"}
    try:
        exec(compiled, ns)
    except MemoryError:
        return _error("memory", "MemoryError while defining the detector", fatal=True)
    except RecursionError as e:
        return _error("runtime", "RecursionError: %s" % e, _tb_line(e.__traceback__), exception="RecursionError")
    except BaseException as e:  # noqa: B036  (SystemExit and KeyboardInterrupt from detector code too)
        return _error("runtime", "%s: %s" % (type(e).__name__, e), _tb_line(e.__traceback__),
                      exception=type(e).__name__)
    fn = ns.get("find_pattern")
    if not callable(fn):
        return _error("no_find_pattern", "the code defines no function `find_pattern(trace)`")
    # Without the Python layer the code can reach anything: it gets every step built, as when it
    # may call dict's methods unbound.
    unbound = not PYTHON_GUARD or ("dict" in names and reads_dict_unbound(tree))
    shared = share_helpers(tree, ns, handlers) if SHARE_HELPERS and fixed and not unbound else ()
    DETECTORS[msg["id"]] = (fn, unbound, shared)
    return {"ok": True}


class _TooBig(Exception):
    pass


def _not_json(o):
    raise TypeError("a value of type %s is not JSON (use dict, list, str, int, float, bool, None)" % type(o).__name__)


def run_detector(detector_id, trace_key):
    detector = DETECTORS.get(detector_id)
    trace = TRACES.get(trace_key)
    if detector is None or trace is None:
        return None, _error("internal", "detector or trace not loaded")
    fn, unbound, shared = detector
    _SHARE_TRACE[0] = trace if shared else None
    if unbound:
        # Before the timer: the eager build's cost is the load's, not the call's. Such a detector may
        # hold the type `dict` and call its methods unbound, which FrozenDict cannot refuse: it reads
        # (and may change) a private copy.
        realise_all(trace)
        trace = _private_copy(trace, {})
    _SINK.take()
    w0 = time.perf_counter()
    c0 = _cpu_clock()
    try:
        out = fn(trace)
    except MemoryError:
        return None, _error("memory", "MemoryError", fatal=True)
    except RecursionError as e:
        return None, _error("runtime", "RecursionError: maximum recursion depth exceeded",
                            _tb_line(e.__traceback__), exception="RecursionError")
    except BaseException as e:  # noqa: B036
        return None, _error("runtime", "%s: %s" % (type(e).__name__, str(e)[:500]),
                            _tb_line(e.__traceback__), exception=type(e).__name__)
    finally:
        _CPU["used"] = _cpu_clock()  # also after a failed call, for the next call's CPU limit
        if shared:
            share_after(shared)
    wall = time.perf_counter() - w0
    cpu = _CPU["used"] - c0
    timing = {"wall": wall, "cpu": cpu}
    if not isinstance(out, list):
        return None, _error("invalid_output", "find_pattern must return a list, found %s" % type(out).__name__,
                            path="$", **timing)
    if len(out) > MAX_PATTERNS:
        return None, _error("invalid_output", "find_pattern returned %d patterns (limit %d)" % (len(out), MAX_PATTERNS),
                            path="$", **timing)
    try:
        # C speed, floats as raw doubles; repeated objects are shared by reference (the Rust reader
        # charges each copy against the output limit). Refuses subclasses of dict and list (the trace's
        # read-only dicts, say): those take the JSON path below.
        body = marshal.dumps(out, 4)
    except (ValueError, TypeError):
        body = None
    except MemoryError:
        return None, _error("memory", "MemoryError while encoding the output", fatal=True)
    if body is not None:
        if len(body) > MAX_OUTPUT_BYTES:
            return None, _error("invalid_output", "the output is over %d bytes (limit %d)" % (MAX_OUTPUT_BYTES, MAX_OUTPUT_BYTES),
                                path="$", **timing)
        printed = _SINK.take()[:1000].encode("utf-8", "replace")
        return b"".join((b"M", _MARSHAL_HEAD.pack(wall, cpu, len(printed)), printed, body)), None
    if _exceeds(out, MAX_OUTPUT_BYTES):
        return None, _error("invalid_output", "the output is over %d bytes (limit %d)" % (MAX_OUTPUT_BYTES, MAX_OUTPUT_BYTES),
                            path="$", **timing)
    try:
        text = json.dumps(out, separators=(",", ":"), allow_nan=False, default=_not_json)
    except MemoryError:
        return None, _error("memory", "MemoryError while encoding the output", fatal=True)
    except RecursionError:
        return None, _error("invalid_output", "the output is nested too deeply", path="$", **timing)
    except (TypeError, ValueError) as e:
        return None, _error("invalid_output", str(e), path="$", **timing)
    if len(text) > MAX_OUTPUT_BYTES:
        return None, _error("invalid_output", "the output is %d bytes (limit %d)" % (len(text), MAX_OUTPUT_BYTES),
                            path="$", **timing)
    printed = _SINK.take()
    head = '{"ok":true,"wall":%r,"cpu":%r,"printed":%s,"patterns":' % (wall, cpu, json.dumps(printed[:1000]))
    return (head + text + "}").encode(), None


def _exceeds(value, budget):
    """Whether the JSON text of `value` is surely longer than `budget` bytes, found by a bounded walk that
    stops as soon as the budget is spent, so a huge output is refused without being encoded. Each value
    counts at least one byte and each string its length, so the walk under-estimates the text and never
    refuses an output that would fit."""
    stack = [value]
    used = 0
    while stack:
        v = stack.pop()
        used += 1
        if isinstance(v, str):
            used += len(v)
        elif isinstance(v, dict):
            for k, item in v.items():
                used += 1 + (len(k) if isinstance(k, str) else 1)
                stack.append(item)
        elif isinstance(v, (list, tuple)):
            used += len(v)
            if used > budget:
                return True
            stack.extend(v)
        if used > budget:
            return True
    return False


def serve():
    while True:
        (n,) = _PACK.unpack(_read_exact(4))
        frame = _read_exact(n)
        kind = frame[:1]
        _set_cpu_limit(CPU_SECONDS)
        try:
            if kind == b"T" or kind == b"P":
                b0 = time.perf_counter()
                gc.disable()
                try:
                    if kind == b"P":
                        key, trace = load_pool_columns(frame)
                        TRACES[key] = trace
                        del trace
                    else:
                        key, trace = load_steps(frame)
                        TRACES[key] = trace
                        del trace
                finally:
                    gc.enable()
                # The cached trace never holds cycles: keep it out of every later collection
                # (CPython; PyPy's generational collector has no `freeze` and does not need it).
                if _GC_FREEZE is not None:
                    _GC_FREEZE()
                _reply({"ok": True, "build": time.perf_counter() - b0})
            elif kind == b"E":
                msg = json.loads(frame[1:])
                # Traces hold no cycles: dropping the last reference frees them, frozen or not, with
                # no collection over the other cached traces.
                for i in msg.get("ids", []):
                    TRACES.pop(i, None)
                # No reply: the Rust side sends this behind a run request and does not wait for it.
            elif kind == b"C":
                _reply(compile_detector(json.loads(frame[1:])))
            elif kind == b"R":
                msg = json.loads(frame[1:])
                # With "flush" (seconds) > 0, replies wait in the outbox and go out together: before a
                # call once that long has passed since the last write, and at the end. Each write wakes
                # the Rust side, which costs about as much as a short call on a virtual machine. The
                # Rust side waits call_timeout + flush for each write.
                flush = float(msg.get("flush") or 0)
                last = time.perf_counter()
                share_begin(msg["detectors"])
                for detector_id in msg["detectors"]:
                    if _OUTBOX and time.perf_counter() - last >= flush:
                        _flush()
                        last = time.perf_counter()
                    _set_cpu_limit(CPU_SECONDS, _CPU["used"])
                    raw, err = run_detector(detector_id, msg["trace"])
                    if raw is not None:
                        _send(raw, flush=not flush)
                    else:
                        _reply(err)
                        last = time.perf_counter()
                        if err["error"].get("fatal"):
                            sys.exit(3)
                share_end()
                _flush()
            else:
                _reply(_error("internal", "unknown message type %r" % kind))
        except MemoryError:
            _reply(_error("memory", "MemoryError", fatal=True))
            sys.exit(3)


def main():
    sys.setrecursionlimit(int(CONFIG.get("recursion_limit", 2000)))
    layers = _lock_down()
    layers["python_guard"] = PYTHON_GUARD
    impl = sys.implementation.name
    version = sys.version.split()[0] if impl == "cpython" else "%s %s" % (impl, sys.version.split()[0])
    _reply({"ok": True, "ready": True, "layers": layers, "python": version})
    serve()


main()
