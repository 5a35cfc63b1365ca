"""Planning and models: pure Python over numpy, no ROS import (see DESIGN.md, Layers)."""
