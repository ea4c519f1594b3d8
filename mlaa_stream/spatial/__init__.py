"""The spatial filter: MLAA passes (edges, distances, weights, blend), bridging and topological reconstruction, each beside its numpy reference."""
