"""Grade against a design surface: the LandXML TIN and the cutting edge's heights
(``design_surface``, numpy; the machine-independent parts, and the forward node's grade outputs,
are in ``manipulator_kinematics``: landxml, site, nodes.surface_grade). Imports ``core`` only."""
