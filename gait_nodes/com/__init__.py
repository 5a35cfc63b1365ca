"""COM generators: ZMP preview control, sway compensation, polynomials, multi-mass correction.

Pure numpy/scipy, no ROS import. The com_preview_controller node wraps them.
"""
