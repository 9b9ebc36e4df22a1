"""Staggered-grid volume-fraction elasticity (dolny-2025): operators, assembly, solvers."""
