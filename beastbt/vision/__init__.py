"""Vision: what is computed from camera images.

``camera_model`` maps between the floor (robot body frame, metres) and image
pixels for a pinhole camera at a known mounting; ``line_detector`` finds a
painted line, its junctions and its end in a frame and reports a
:class:`~beastbt.blackboard.types.LineObservation`. Images come from
:class:`beastbt.devices.camera.Camera` (real or simulated); nothing here
touches devices, the clock or the blackboard.
"""
