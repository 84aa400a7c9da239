"""Contextual inference in skill memory separation and expression (paper, Results 2).

A Sheahan et al. (2016)-inspired reaching task in the Panda's task space, the Neural
ASM against two BPTT-trained RNN baselines, and two side results: the speed-accuracy
trade-off of iterative inference and learning speed against the number of skills.
"""
