"""The student's GUI: ``pendulab gui``, a local web page over pendulab's Python API (see :mod:`pendulab.gui.server`)."""
