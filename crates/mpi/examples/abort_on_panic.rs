//! A rank that panics under `mpirun` ends the whole job instead of leaving the other ranks
//! waiting for it: `lucent_mpi::World::initialise` installs a panic hook that calls
//! `MPI_Abort` after the usual message. Here rank 1 panics while rank 0 waits in a gather
//! that rank 1 never joins; the job must end at once with a failure (CI runs it under a
//! timeout).
//!
//! ```sh
//! cargo build -p lucent-mpi --features mpi --example abort_on_panic
//! mpirun -n 2 target/debug/examples/abort_on_panic   # fails at once, exit status ≠ 0
//! ```

#[cfg(feature = "mpi")]
fn main() {
    use lucent_mpi::Communicator;
    let world = lucent_mpi::World::initialise().expect("MPI starts");
    let ranks = world.ranks();
    if ranks.rank() == 1 {
        panic!("rank 1 panics on purpose");
    }
    let gathered = ranks.all_gather(&[0.0]);
    // Only reached if the panicking rank joined the gather after all.
    #[allow(clippy::print_stderr)]
    {
        eprintln!("rank {} passed a gather of {gathered:?}", ranks.rank());
    }
}

#[cfg(not(feature = "mpi"))]
#[allow(clippy::print_stderr)]
fn main() {
    eprintln!("abort_on_panic: build with --features mpi and run under mpirun -n 2");
}
