"""Offline tools and the registry's hooks: bag evaluation and synthetic bags, the scene for
markers and animations, the working-range diagram."""
