"""Tuna et al. (T-RO 2013): its published tables beside ours, and which of its findings
reproduce (``rhmpc compare --paper``).

============  ==================================================================
``tuna2013``  the published cells of Tables I–III
``tables``    our cells beside the published ones, with their ratio
``findings``  each published finding judged on our runs, over seeds
============  ==================================================================

Imports :mod:`rhmpc.compare` (the cells and their intervals) and the layers below.
"""
