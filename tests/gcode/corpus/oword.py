# O-word procedures of the corpus programs py_*.ngc: `o<name> call [args]` runs name(self,
# *args) when the ini's [PYTHON] TOPLEVEL (pysubs.py) has imported this module.
import emccanon
import interpreter


def py_rectangle(self, width, height):
    """A rectangle from the current corner, at the depth and feed of the ini's [PART]."""
    x0 = self.params["_ini[part]x0"]
    y0 = self.params["_ini[PART]Y0"]
    depth = self.params["_ini[part]depth"]
    emccanon.COMMENT("rectangle %g x %g" % (width, height))
    emccanon.SET_FEED_RATE(self.params["_ini[part]feed"])
    emccanon.STRAIGHT_TRAVERSE(0, x0, y0, 2.0, 0, 0, 0, 0, 0, 0)
    emccanon.STRAIGHT_FEED(0, x0, y0, depth, 0, 0, 0, 0, 0, 0)
    corners = [(x0 + width, y0), (x0 + width, y0 + height), (x0, y0 + height), (x0, y0)]
    for i, (x, y) in enumerate(corners):
        emccanon.STRAIGHT_FEED(i + 1, x, y, depth, 0, 0, 0, 0, 0, 0)
        print("corner %d at %.3f %.3f" % (i + 1, x, y))
    emccanon.DWELL(0.5)
    emccanon.MESSAGE("rectangle done, work offset %d" % self.params[5220])
    emccanon.STRAIGHT_TRAVERSE(0, x0, y0, 2.0, 0, 0, 0, 0, 0, 0)
    return width * height


def py_coolant(self, on):
    if on:
        emccanon.MIST_ON()
        emccanon.FLOOD_ON()
    else:
        emccanon.FLOOD_OFF()
        emccanon.MIST_OFF()


def py_half(self, x):
    return x / 2.0


def py_none(self, *args):
    return None


def py_no_return(self, *args):
    self.calls += 1


def py_args(self, *args):
    print("%d arguments: %s" % (len(args), " ".join("%.2f" % a for a in args)))
    return float(len(args))


def py_remember(self, value):
    self.remembered = value
    self.calls += 1


def py_recall(self):
    if not hasattr(self, "remembered"):
        return "nothing remembered"
    print("remembered %.1f after %d calls; this is self: %s"
          % (self.remembered, self.calls, self is interpreter.this))
    return self.remembered


def py_params(self, *args):
    # numbered parameters are the caller's (#1 is not an argument here); a named local
    # lives in this call only; globals stay
    print("#1 = %.1f, #5220 = %.0f, _total = %.1f"
          % (self.params[1], self.params[5220], self.params["_total"]))
    self.params[1] = self.params[1] + 1
    self.params["_total"] = self.params["_total"] * 2
    self.params["scratch"] = 5
    print("scratch = %.1f, call level %d" % (self.params["scratch"], self.call_level))


def py_fails(self, x):
    return 1.0 / x


def py_refuses(self):
    return "the part is not clamped"


def py_int(self):
    return 3
