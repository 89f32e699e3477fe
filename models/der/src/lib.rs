//! Discrete elastic rod (Bergou 2008/2010): guidewire, catheter, needle (work in progress).
