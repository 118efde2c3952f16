"""A flatter surface by moving vertices outward (eq. 4-21): the objective, gradient descent and L-PSO."""
