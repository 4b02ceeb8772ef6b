//! Linear-Gaussian controllers: the policy type and its initialisations.
pub mod init;
pub mod lin_gauss;
