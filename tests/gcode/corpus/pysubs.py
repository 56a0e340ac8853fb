# TOPLEVEL of the corpus programs py_*.ngc (their .ini files name it): run once when the
# interpreter starts Python. As LinuxCNC does, the functions of the module `oword` it imports
# are O-word procedures; `__init__` runs with the interpreter object once this file has run.
import interpreter
import oword

started = 0


def __init__(self):
    global started
    started += 1
    self.calls = 0
    self.startup_is_this = self is interpreter.this
