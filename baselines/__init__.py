"""Baselines for SoftSphere: the paper's regressors as policies, SB3 agents, and the benchmark."""
