//! The realtime core: the Orocos hybrid task model (activities on SCHED_FIFO threads, data
//! objects, buffers, events, commands, lifecycle and timing statistics).
