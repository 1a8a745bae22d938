"""The excavator's ROS 2 nodes (console scripts) and what serves only them: settings schemas,
message codecs, input handling and display outputs. Imports ``core``, ``sensing`` and ``grade``."""
