"""DH tables synthesised for manipulability (Sobh & Toundykov, paper 004)."""
