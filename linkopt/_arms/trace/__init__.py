"""Planar arms that trace continuous paths around obstacles (Campos et al.,
paper 002)."""
