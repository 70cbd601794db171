"""Peer implementations of gnc_jax's studies in the tools users would pick instead."""
