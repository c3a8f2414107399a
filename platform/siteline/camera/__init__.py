"""Cameras: the pinhole camera and its intrinsics (``pinhole``: ``Camera``, ``Intrinsics``, the one
pycolmap conversion), named capture cameras (``intrinsics``), ``Rigid``/``Sim3`` poses with frame names
(``poses``), DJI gimbal angles and grid convergence (``dji``), and DJI photo metadata (``photos``)."""
