//! Deployment of a machine: builds HAL backends, tasks and threads from the configuration,
//! checks the topology and runs the machine state machine and its safety paths.

pub mod api;
pub mod mode;
pub mod safety;
