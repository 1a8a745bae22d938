"""Offline tools and the registry's bag and scene hooks: bag evaluation and synthetic bags, the scene for
markers and animations, the working-range diagram."""
