#!/usr/bin/env python3
"""Runs Debian's dxf2gcode (20191025) on Python >= 3.10, whose PyQt5 no longer turns
floats into ints implicitly: the few Qt calls dxf2gcode makes with floats are wrapped to
round them. Nothing of the G-code generation is changed. Usage as dxf2gcode's."""
import runpy
import sys

from PyQt5 import QtCore, QtGui, QtWidgets


def _int_args(cls, name):
    orig = getattr(cls, name)

    def wrapped(self, *a, **k):
        return orig(self, *[int(round(x)) if isinstance(x, float) else x for x in a], **k)

    setattr(cls, name, wrapped)


class _Font(QtGui.QFont):
    def __init__(self, *a):
        super().__init__(*[int(round(x)) if isinstance(x, float) else x for x in a])


QtGui.QFont = _Font
_int_args(QtWidgets.QScrollBar, "setValue")
_int_args(QtWidgets.QAbstractSlider, "setValue")
_int_args(QtCore.QTimer, "start")
sys.argv[0] = "/usr/bin/dxf2gcode"
runpy.run_path("/usr/bin/dxf2gcode", run_name="__main__")
