"""Serial arms on the same engine.

``chain`` builds the serial chain every family hands to the engine (its mechanism
definition and its closed-form state); ``codesign`` is design + trajectory optimisation
with obstacles, torque limits and joint elimination (paper 000); ``dh`` is
manipulability-driven DH synthesis (paper 004); ``trace`` is the synthesis of planar
arms tracing paths around obstacles (paper 002); ``checks`` holds the argument checks
they share.
"""
