"""pendulab: the cart-and-pendulum control lab as standard FMI components.

The plant (one CasADi model, compiled into a native FMU), the student's controller and the safety
supervisor are each an FMU, wired by a co-simulation master on fmpy.
"""

__version__ = "0.1.0"
