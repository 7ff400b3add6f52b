"""The page's parts, built with NiceGUI: one module per tab, the settings form, the job panel.

Each module imports NiceGUI at its top, so only :func:`mjx_pick.gui.app.build_page`
imports them (when the server builds a page): ``import mjx_pick.gui`` never loads the web
framework. They import only downward: a tab uses the parts (``widgets``,
``settings_form``, ``job_panel``) and the framework-free modules of ``mjx_pick.gui``,
never another tab (``tests/test_layers.py``); ``app`` wires tabs to each other.
"""
