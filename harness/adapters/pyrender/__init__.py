"""pyrender (OSMesa, headless): Monte Carlo over a rasterizer (``render``) on scenes built in
code (``scenes``).  OpenGL is imported only when ``render`` is."""
