"""The serial arms' figures: :mod:`.codesign` (paper 000), :mod:`.dh` (paper 004) and
:mod:`.trace` (paper 002), drawn from the results of :mod:`linkopt._arms`."""
