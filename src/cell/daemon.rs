//! Serving the cell on the control socket (filled below).
