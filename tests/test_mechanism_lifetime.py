"""What linkopt remembers of a mechanism does not keep it alive: a caller that drops a
mechanism gets its memory back (a sweep over thousands of generated files must not
grow without bound)."""

import gc
import weakref

from conftest import MECHANISMS

import linkopt
from linkopt._design.conditioning import alpha_minus


def test_alpha_minus_is_remembered_without_keeping_the_mechanism_alive():
    mech = linkopt.load(MECHANISMS / "five_bar.toml")
    first = alpha_minus(mech)
    assert first > 0 and alpha_minus(mech) == first  # computed once, the same value
    ref = weakref.ref(mech)
    del mech
    gc.collect()
    assert ref() is None
