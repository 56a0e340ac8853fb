# hytask's bridge to the interpreter's embedded Python (src/gcode/python.rs runs it as
# `python3 -B -c <loader> <this file> <config json>`, compiled as file BRIDGE).
#
# It gives Python code the view LinuxCNC's interpreter gives it: an `interpreter` module whose
# `this` is the interpreter object (`self` of every O-word procedure), an `emccanon` module of
# canonical calls, and `self.params` for the interpreter's parameters. Nothing here is
# LinuxCNC's code: every call is forwarded to hytask's interpreter over the pipes.
#
# Protocol: one JSON object per line. hytask sends requests on stdin ({"op": "has" | "call" |
# "exec", ...}); while one runs, this side sends events ({"ev": "print" | "get" | "set" |
# "canon", ...}; get/set/canon wait for hytask's reply) and ends it with {"ev": "done", ...} or
# {"ev": "error", ...}. Start-up ends with {"ev": "ready"} or {"ev": "error"}. The protocol
# has its own copies of file descriptors 0 and 1; Python's own stdout is captured and sent
# as print events (so it lands in the trace where rs274 prints it), fd 1 itself goes to
# stderr and fd 0 reads /dev/null.
import json
import os
import sys
import traceback
import types

BRIDGE = "<hytask bridge>"

_proto_in = os.fdopen(os.dup(0), "r", encoding="utf-8")
_proto_out = os.fdopen(os.dup(1), "w", encoding="utf-8")
_null = os.open(os.devnull, os.O_RDONLY)
os.dup2(_null, 0)
os.close(_null)
os.dup2(2, 1)


def _send(obj):
    _proto_out.write(json.dumps(obj) + "\n")
    _proto_out.flush()


def _recv():
    line = _proto_in.readline()
    if not line:
        os._exit(0)
    return json.loads(line)


class _Refused(Exception):
    pass


def _ask(obj):
    _send(obj)
    r = _recv()
    if "error" in r:
        kind = r.get("kind")
        if kind == "key":
            raise KeyError(r["error"])
        if kind == "stop":
            # hytask refused a canonical call (a limit): stop the Python code
            raise _Refused(r["error"])
        raise RuntimeError(r["error"])
    return r


class _Stdout:
    """sys.stdout: Python's output goes to hytask's trace."""

    encoding = "utf-8"

    def write(self, s):
        if s:
            _send({"ev": "print", "text": str(s)})
        return len(s)

    def flush(self):
        pass

    def isatty(self):
        return False


sys.stdout = _Stdout()


def _key(k):
    if isinstance(k, str):
        return k
    if isinstance(k, (int, float)) and not isinstance(k, bool):
        return float(k)
    raise TypeError("parameter key must be a name or a number, not %s" % type(k).__name__)


class Params:
    """`self.params[...]`: hytask's numbered and named parameters."""

    def __getitem__(self, k):
        return _ask({"ev": "get", "key": _key(k)})["value"]

    def __setitem__(self, k, v):
        _ask({"ev": "set", "key": _key(k), "value": float(v)})

    def __contains__(self, k):
        try:
            self[k]
            return True
        except KeyError:
            return False


class Interp:
    """The interpreter as Python sees it (`interpreter.this`, `self`)."""

    def __init__(self):
        self.params = Params()

    @property
    def return_value(self):
        return float(self.params["_value"])

    @property
    def value_returned(self):
        return int(self.params["_value_returned"])

    @property
    def call_level(self):
        return int(_ask({"ev": "level"})["value"])


TOLERANCE_EQUAL = 0.0001

interpreter = types.ModuleType("interpreter")
interpreter.this = Interp()
interpreter.Interp = Interp
interpreter.TOLERANCE_EQUAL = TOLERANCE_EQUAL
interpreter.equal = lambda a, b: abs(a - b) < TOLERANCE_EQUAL
interpreter.is_near_int = lambda v: abs(v - round(v)) < TOLERANCE_EQUAL
interpreter.nearest_int = lambda v: int(v + 0.5) if v >= 0 else int(v - 0.5)
for _i, _n in enumerate(["INTERP_OK", "INTERP_EXIT", "INTERP_EXECUTE_FINISH",
                         "INTERP_ENDFILE", "INTERP_FILE_NOT_OPEN", "INTERP_ERROR"]):
    setattr(interpreter, _n, _i)
interpreter.INTERP_MIN_ERROR = 3
interpreter.throw_exceptions = 1


class InterpreterException(Exception):
    pass


interpreter.InterpreterException = InterpreterException
sys.modules["interpreter"] = interpreter

emccanon = types.ModuleType("emccanon")


def _canon(name, *args, text=None):
    msg = {"ev": "canon", "name": name, "args": [float(a) for a in args]}
    if text is not None:
        msg["text"] = str(text)
    _ask(msg)


def _pose_call(name):
    def call(line, x, y, z, a, b, c, u, v, w):
        _canon(name, x, y, z, a, b, c, u, v, w)
    call.__name__ = name
    return call


emccanon.STRAIGHT_FEED = _pose_call("STRAIGHT_FEED")
emccanon.STRAIGHT_TRAVERSE = _pose_call("STRAIGHT_TRAVERSE")
emccanon.MESSAGE = lambda s: _canon("MESSAGE", text=s)
emccanon.COMMENT = lambda s: _canon("COMMENT", text=s)
emccanon.SET_FEED_RATE = lambda f: _canon("SET_FEED_RATE", f)
emccanon.DWELL = lambda s: _canon("DWELL", s)
for _n in ["MIST_ON", "MIST_OFF", "FLOOD_ON", "FLOOD_OFF"]:
    setattr(emccanon, _n, (lambda n: lambda: _canon(n))(_n))


def _unsupported(name):
    def call(*args, **kwargs):
        raise NotImplementedError("emccanon.%s is not supported by hytask" % name)
    return call


emccanon.__getattr__ = _unsupported
sys.modules["emccanon"] = emccanon


def _error(e):
    """An exception as an error event: its last line, and where in Python it was raised."""
    tb = traceback.extract_tb(e.__traceback__)
    frames = [f for f in tb if f.filename != BRIDGE]
    at = "%s:%d" % (frames[-1].filename, frames[-1].lineno) if frames else ""
    text = "".join(traceback.format_exception_only(type(e), e)).strip()
    return {"ev": "error", "msg": text, "at": at}


def _main():
    cfg = json.loads(sys.argv[-1])
    sys.path[:0] = cfg.get("prepend", [])
    sys.path.extend(cfg.get("append", []))
    ns = {"__name__": "__main__", "sys": sys}
    this = interpreter.this
    try:
        top = cfg.get("toplevel")
        if top:
            ns["__file__"] = top
            with open(top, encoding="utf-8") as f:
                code = compile(f.read(), top, "exec")
            exec(code, ns)
            init = ns.get("__init__")
            if callable(init):
                init(this)
    except BaseException as e:  # noqa: B902 - reported to hytask, whatever it is
        _send(_error(e))
        return
    _send({"ev": "ready"})
    while True:
        req = _recv()
        op = req.get("op")
        try:
            if op == "has":
                oword = ns.get("oword")
                fn = getattr(oword, req["name"], None) if oword is not None else None
                _send({"ev": "done", "kind": "bool", "value": callable(fn)})
            elif op == "call":
                fn = getattr(ns.get("oword"), req["name"])
                r = fn(this, *req["args"])
                if r is None:
                    _send({"ev": "done", "kind": "none"})
                elif isinstance(r, float):
                    _send({"ev": "done", "kind": "float", "value": r})
                elif isinstance(r, str):
                    _send({"ev": "done", "kind": "str", "value": r})
                else:
                    _send({"ev": "done", "kind": type(r).__name__, "value": repr(r)})
            elif op == "exec":
                exec(compile(req["code"], "<string>", "exec"), ns)
                _send({"ev": "done", "kind": "none"})
            else:
                _send({"ev": "error", "msg": "unknown request %r" % op, "at": ""})
        except BaseException as e:  # noqa: B902 - reported to hytask, whatever it is
            _send(_error(e))


_main()
