"""Grade against a design surface: the LandXML TIN and the cutting edge's heights
(``design_surface``, numpy) and the forward node's grade outputs (``surface_grade``). Imports
``core`` only."""
