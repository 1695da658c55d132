"""Heart motion described, as ``rhmpc data`` lists, shows, exports and plots it: a named
scenario or a recording.

===========  ==================================================================
``targets``  what an action works on (a scenario with its overrides, or a recording), the
             memory and time the work takes, checked before it starts; its export
``tables``   what each scenario replicates, and the statistics measured on a motion
``figure``   the figure of ``data plot``: positions, heart rate, power spectral density
``text``     numbers in messages: significant digits, lengths, sizes and spans
===========  ==================================================================

Imports :mod:`rhmpc.sim` and the layers below.
"""
