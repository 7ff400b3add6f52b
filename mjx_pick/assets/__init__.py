"""Shipped data: object images and meshes, gripper presets, example outcome files.

Installed as ``mjx_pick.assets``; read with ``importlib.resources``.
"""
