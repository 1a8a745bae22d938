"""The demo (``excavator_demo``), its scripted bucket paths, planned moves and cycle report, and the
slope example."""
