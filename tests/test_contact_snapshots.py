"""The contact's FMU-state copies (``snapshot()`` of ImpactResolver, HostObserver,
PlausibilityWatch, PlainContact) are as independent as ``copy.deepcopy``'s and continue exactly
as the original does.

The oracle is ``copy.deepcopy``, what the FMU state used before: a snapshot and a deep copy taken
at the same point, then stepped with the same inputs, must give bit-identical outcomes and
attributes; and nothing that can change in place may be shared between a snapshot and its
original (a walk over both object graphs).
"""
from __future__ import annotations

import copy
import dataclasses
import math
import types

import pytest

from fmu_src.contact_laws import law_for
from fmu_src.plain_contact import PlainContact
from fmu_src.plausibility import PlausibilityWatch
from fmu_src.resolver import ImpactResolver

#: shared on purpose: built by ImpactResolver.__init__ from the law and never changed after
SHARED_TABLES = {"_kernels"}


def shared_mutables(a, b, path="", seen=None):
    """Paths of objects reachable from both ``a`` and ``b`` (the same object) that can change in
    place: lists, dicts, sets, arrays, instances that are not frozen dataclasses."""
    seen = set() if seen is None else seen
    if id(a) in seen:
        return []
    seen.add(id(a))
    if a is b:
        if a is None or isinstance(a, (bool, int, float, complex, str, bytes, frozenset,
                                       types.FunctionType, types.BuiltinFunctionType, type)):
            return []
        if isinstance(a, tuple):
            return [p for i, x in enumerate(a) for p in shared_mutables(x, x, f"{path}[{i}]", seen)]
        if dataclasses.is_dataclass(a) and a.__dataclass_params__.frozen:
            return []
        if path.rsplit(".", 1)[-1] in SHARED_TABLES:
            return []
        return [path]
    if isinstance(a, (list, tuple)) and isinstance(b, (list, tuple)) and len(a) == len(b):
        return [p for i, (x, y) in enumerate(zip(a, b)) for p in shared_mutables(x, y, f"{path}[{i}]", seen)]
    if isinstance(a, dict) and isinstance(b, dict):
        return [p for k in a if k in b for p in shared_mutables(a[k], b[k], f"{path}[{k!r}]", seen)]
    if hasattr(a, "__dict__") and type(a) is type(b) and not isinstance(a, type):
        return [p for k, v in vars(a).items() for p in shared_mutables(v, vars(b).get(k), f"{path}.{k}", seen)]
    return []


def same(x, y) -> bool:
    """Equal, NaN equal to NaN (last_CR before the first completed impact)."""
    if isinstance(x, float) and isinstance(y, float) and math.isnan(x) and math.isnan(y):
        return True
    return x == y


def plain_state(obj) -> dict:
    out = {}
    for k, v in vars(obj).items():
        if isinstance(v, (bool, int, float, str, tuple, type(None))):
            out[k] = v
        elif isinstance(v, list):
            out[k] = tuple(v)
        elif k in ("observer", "_watch"):
            out[k] = plain_state(v)
    return out


def states_equal(a, b) -> bool:
    sa, sb = plain_state(a), plain_state(b)
    return sa.keys() == sb.keys() and all(same(sa[k], sb[k]) or repr(sa[k]) == repr(sb[k]) for k in sa)


class FreeMasses:
    """Two free masses held at the contact's mean force over each step (zero-order hold, exact)."""

    def __init__(self, contact, m: float, v: float, h: float):
        self.contact, self.m, self.h = contact, m, h
        self.delta, self.rate = -0.5 * v * h, v

    def step(self, declared=False):
        out = self.contact.step(self.delta, self.rate, self.h, declared)
        F = out.mean_force if hasattr(out, "mean_force") else out
        self.delta += self.rate * self.h - 0.5 * F / self.m * self.h * self.h
        self.rate -= F / self.m * self.h
        return out


@pytest.mark.parametrize("model", ["jankowski", "crvk", "hertzdamp"])
@pytest.mark.parametrize("kind", ["resolver", "plain"])
def test_snapshot_continues_as_a_deep_copy(model, kind):
    law = law_for(model, 2.75e9, 1.5, 1e5, 1e5, 0.65)
    v, m = 0.5, law.m
    contact = ImpactResolver(law) if kind == "resolver" else PlainContact(law)
    if kind == "resolver":
        contact.trace = []
    # h: a few steps through the contact (resolver), or fine enough for the plain law
    h = 2e-3 if kind == "resolver" else 5e-5
    host = FreeMasses(contact, m, v, h)
    watch = PlausibilityWatch(law)
    for i in range(400):
        host.step()
        watch.check(contact, h)
        if contact.in_contact and contact.impact_time > 0.0 and i > 2:
            break
    assert contact.in_contact                      # saved mid-impact: the hardest state
    snap, deep = contact.snapshot(), copy.deepcopy(contact)
    wsnap, wdeep = watch.snapshot(), copy.deepcopy(watch)
    assert shared_mutables(snap, contact) == []
    assert shared_mutables(wsnap, watch) == []
    assert states_equal(snap, deep) and states_equal(wsnap, wdeep)
    # the original moves on; its snapshot and the deep copy, given the same inputs, stay identical
    start = (host.delta, host.rate)
    for _ in range(50):
        host.step()
        watch.check(contact, h)
    runs = []
    for c, w in ((snap, wsnap), (deep, wdeep)):
        host.contact, (host.delta, host.rate) = c, start
        outs = []
        for _ in range(50):
            out = host.step()
            outs.append(repr(out))
            outs.append(repr(w.check(c, h)))
        runs.append((outs, c, w))
    (o1, c1, w1), (o2, c2, w2) = runs
    assert o1 == o2
    assert states_equal(c1, c2) and states_equal(w1, w2)
    assert states_equal(c1, contact)                 # and the original, which took the same steps
    if kind == "resolver":
        assert c1.ended >= 1 and c1.trace == c2.trace == contact.trace


def test_snapshot_copies_the_lists():
    law = law_for("jankowski", 2.75e9, 1.5, 1e5, 1e5, 0.65)
    r = ImpactResolver(law)
    r.trace = [(1, 0.0, 0.0, 0.0)]
    r.observer.notices.append("a notice")
    s = r.snapshot()
    r.trace.append((2, 0.0, 0.0, 0.0))
    r.observer.notices.clear()
    assert s.trace == [(1, 0.0, 0.0, 0.0)] and s.observer.notices == ["a notice"]
    assert s.law is r.law and s._kernels is r._kernels     # shared: frozen, and never changed
