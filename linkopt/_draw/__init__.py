"""Drawing: figures, maps, animations and the browser view.

Depends on the core (engine, files, export, design, arms, synthesis); nothing below
it draws or imports matplotlib.
"""
