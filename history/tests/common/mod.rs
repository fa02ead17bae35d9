pub mod drift_sim;
pub mod nights;
