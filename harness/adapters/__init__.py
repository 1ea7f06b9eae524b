"""Adapters: real renderers and their samplers, measured like the core's estimators.

A renderer adapter turns a scene and its settings into a ``Renderer`` (see ``base``): it
renders at a budget (samples or frames per pixel) and a seed and returns a float image and
its wall time.  Renderer modules are imported only when a suite or test uses them, so a
suite of core cases never imports Mitsuba or OpenGL.
"""
from harness.adapters.base import ADAPTERS, ImageFaults, Render, Renderer, image_faults, renderer

__all__ = ["ADAPTERS", "ImageFaults", "Render", "Renderer", "image_faults", "renderer"]
