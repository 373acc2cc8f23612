"""Nodes: onboard node, Spinal mirror, Neuron mirror, plant node and their scheduler."""
