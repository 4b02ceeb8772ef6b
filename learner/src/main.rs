//! `learner`: the command line ([`learner::cli`]).

fn main() -> anyhow::Result<()> {
    learner::cli::main()
}
