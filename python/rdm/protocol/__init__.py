"""Wire codecs: rosserial frames and Spinal messages, Neuron CAN frames, Leptrino sensor frames."""
