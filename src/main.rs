//! The `lucent` command.
//!
//! Scenes, solvers and rendering arrive with the crates that provide them. Until then the
//! default job prints the optics of the built-in default materials (Jensen et al. 2001):
//! the derived diffusion parameters and the dipole against the exact Robin half-space.

use std::io::{self, Write};
use std::process::ExitCode;

use lucent::optics::materials::{JENSEN_2001, LENGTH_UNIT};
use lucent::optics::{Dielectric, DiffuseFresnel, DiffusionMedium, OpticsError};

const USAGE: &str = "\
lucent: light transport in participating media

USAGE:
    lucent            print the diffusion optics of the measured materials (default job)
    lucent --help     this text
    lucent --version  the version
";

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let mut out = io::stdout().lock();
    let result = match args
        .iter()
        .map(String::as_str)
        .collect::<Vec<_>>()
        .as_slice()
    {
        [] => materials_table(&mut out),
        ["--help" | "-h"] => write!(out, "{USAGE}").map_err(Error::from),
        ["--version" | "-V"] => {
            writeln!(out, "lucent {}", env!("CARGO_PKG_VERSION")).map_err(Error::from)
        }
        other => Err(Error::Usage(other.join(" "))),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(Error::Io(e)) if e.kind() == io::ErrorKind::BrokenPipe => ExitCode::SUCCESS,
        Err(e) => {
            let _ = writeln!(io::stderr(), "lucent: {e}");
            ExitCode::FAILURE
        }
    }
}

#[derive(Debug)]
enum Error {
    Io(io::Error),
    Optics(OpticsError),
    Usage(String),
}

impl std::fmt::Display for Error {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Error::Io(e) => write!(f, "{e}"),
            Error::Optics(e) => write!(f, "{e}"),
            Error::Usage(args) => write!(f, "unexpected arguments `{args}`\n\n{USAGE}"),
        }
    }
}

impl From<io::Error> for Error {
    fn from(e: io::Error) -> Self {
        Error::Io(e)
    }
}

impl From<OpticsError> for Error {
    fn from(e: OpticsError) -> Self {
        Error::Optics(e)
    }
}

/// One row per material and channel: reduced albedo, D, σ_tr, z_r, z_v, the dipole's total
/// diffuse reflectance and the exact Robin half-space value it approximates.
fn materials_table(out: &mut impl Write) -> Result<(), Error> {
    writeln!(
        out,
        "Diffusion optics of Jensen et al. 2001's measured materials (lengths in {LENGTH_UNIT}, Groenhuis A)"
    )?;
    writeln!(
        out,
        "{:<11} {:>2} {:>9} {:>9} {:>9} {:>9} {:>9} {:>9} {:>9} {:>9}",
        "material", "ch", "albedo'", "D", "sigma_tr", "z_r", "z_v", "R dipole", "R exact", "error"
    )?;
    for material in &JENSEN_2001 {
        let boundary = Dielectric::new(material.eta)?;
        for (channel, name) in ["R", "G", "B"].into_iter().enumerate() {
            let medium = DiffusionMedium::with_boundary(
                material.channel(channel, 0.0)?,
                boundary,
                DiffuseFresnel::Groenhuis,
            )?;
            let dipole = medium.dipole();
            let c = medium.coefficients();
            let rho = dipole.total_reflectance();
            // Spectralon does not absorb: the exact half-space then reflects everything.
            let exact = if c.sigma_a() > 0.0 {
                dipole.total_reflectance_exact()?
            } else {
                1.0
            };
            writeln!(
                out,
                "{:<11} {:>2} {:>9.5} {:>9.5} {:>9.5} {:>9.5} {:>9.5} {:>9.5} {:>9.5} {:>+7.2}%",
                material.name,
                name,
                c.albedo_reduced(),
                medium.d(),
                medium.sigma_tr(),
                medium.z_r(),
                medium.z_v(),
                rho,
                exact,
                100.0 * (rho - exact) / exact
            )?;
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn default_job_prints_every_material_with_the_dipole_against_the_exact_half_space() {
        let mut out = Vec::new();
        materials_table(&mut out).expect("the table is written");
        let text = String::from_utf8(out).expect("utf-8");
        // Header, column names, and 12 materials × 3 channels.
        assert_eq!(text.lines().count(), 2 + 36);
        // Marble red: R dipole 0.86654 and the exact Robin half-space 0.86633 (note 002, T4/T5).
        let marble_red = text
            .lines()
            .find(|l| l.starts_with("Marble") && l.contains(" R "))
            .expect("marble row");
        assert!(
            marble_red.contains("0.86654") && marble_red.contains("0.86633"),
            "{marble_red}"
        );
        // Ketchup green is where diffusion fails: the dipole is off by almost a factor of two.
        let ketchup_green = text
            .lines()
            .find(|l| l.starts_with("Ketchup") && l.contains(" G "))
            .expect("ketchup row");
        assert!(ketchup_green.contains("+95."), "{ketchup_green}");
    }
}
