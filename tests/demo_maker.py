"""fixtures/make_demo.py (the script that makes the shipped demo) as a module, for tests that make small media with
it; ROOT: the repository."""
from __future__ import annotations

import importlib.util
import os

ROOT = os.path.join(os.path.dirname(__file__), "..")
_spec = importlib.util.spec_from_file_location("make_demo", os.path.join(ROOT, "fixtures", "make_demo.py"))
make_demo = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(make_demo)
