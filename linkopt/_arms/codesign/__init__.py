"""Co-design of a serial arm and its trajectory (Whitman & Choset, paper 000)."""
