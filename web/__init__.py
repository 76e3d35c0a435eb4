"""HydroHIL browser monitor and operator panel (viser).

``links`` (where the plant state comes from: the in-process service or a remote server's REST +
WebSocket), ``scene`` (the URDF robot, cylinders between their pins, pressure colours), ``panel``
(the operator GUI), ``viewer`` (the viser server and its render thread), ``plugin`` (what
``hydrohil serve`` loads) and ``cli`` (``hydrohil view``). Depends on sim_core; talks to hil_server
only through ``HilService`` or its REST API.
"""
