pub mod nights;
