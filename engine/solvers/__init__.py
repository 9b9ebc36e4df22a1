"""Linear solvers shared by the methods: preconditioned CG and rigid-body mode handling."""
