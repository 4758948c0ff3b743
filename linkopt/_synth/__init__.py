"""Linkage synthesis: path, function and motion generation (seed 001, Sec. I).

A target curve, function or pose list for a named point, output or body; designs
that meet it over a whole cycle with no singularity, on one branch and in order.
"""
