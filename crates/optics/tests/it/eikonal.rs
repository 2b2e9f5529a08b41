//! Curved rays against closed forms: a uniform index (straight lines, to rounding), a
//! linear gradient (catenaries), Luneburg's lens (parallel rays focus on the far rim).

use glam::DVec3;
use lucent_optics::eikonal::{IndexField, LinearIndex, Luneburg, RaySettings, UniformIndex, trace};
use proptest::prelude::*;

proptest! {
    #[test]
    fn a_uniform_index_gives_straight_rays_to_rounding(
        eta in 1.0f64..3.0,
        start in proptest::array::uniform3(-5.0f64..5.0),
        direction in proptest::array::uniform3(-1.0f64..1.0),
        length in 0.1f64..20.0,
    ) {
        let d = DVec3::from_array(direction);
        prop_assume!(d.length() > 0.1);
        let d = d.normalize();
        let start = DVec3::from_array(start);
        let settings = RaySettings::for_scale(1.0, 1e-9);
        let end = trace(&UniformIndex(eta), start, d, length, &settings, |_| true).unwrap();
        // Every step is an exact segment; what is left is the rounding of ~200 additions.
        let want = start + d * length;
        prop_assert!((end.position - want).length() < 1e-12 * (1.0 + want.length()) * 200.0,
            "{:?} against {:?}", end.position, want);
        prop_assert!((end.arc_length - length).abs() < 1e-12 * length * 200.0);
    }

    #[test]
    fn a_linear_gradient_bends_rays_into_catenaries(
        eta0 in 1.0f64..2.0,
        slope in 0.05f64..0.5,
        angle in 0.05f64..1.2,
        length in 0.5f64..4.0,
    ) {
        // η = a + b y, a ray from the origin at angle θ₀ above +x. The component of
        // v = η dx/ds along x is conserved, c = a cos θ₀, so η(x) = c cosh(b (x − x₀)/c)
        // with x₀ = −(c/b) arccosh(a/c), and ds/dx = η/c gives
        // s(x) = (c/b)(sinh(b(x − x₀)/c) − sinh(−b x₀/c)).
        let (a, b) = (eta0, slope);
        let field = LinearIndex { eta0: a, gradient: DVec3::new(0.0, b, 0.0), origin: DVec3::ZERO };
        let c = a * angle.cos();
        let x0 = -(c / b) * (a / c).acosh();
        let x_at = |s: f64| x0 + (c / b) * (s * b / c + (-b * x0 / c).sinh()).asinh();
        let y_at = |x: f64| (c * (b * (x - x0) / c).cosh() - a) / b;
        let settings = RaySettings::for_scale(1.0, 1e-9);
        let start = DVec3::new(angle.cos(), angle.sin(), 0.0);
        let end = trace(&field, DVec3::ZERO, start, length, &settings, |_| true).unwrap();
        let x = x_at(length);
        let want = DVec3::new(x, y_at(x), 0.0);
        // The step control's tolerance is 1e-9 per unit length; the issue asks 1e-4 of the
        // length: assert 1e-6, room for the accumulated local errors of a few hundred steps.
        prop_assert!((end.position - want).length() < 1e-6 * length,
            "{:?} against {:?}", end.position, want);
    }
}

#[test]
fn luneburg_lens_focuses_parallel_rays_on_its_far_rim() {
    let lens = Luneburg {
        centre: DVec3::new(0.3, -0.2, 0.1),
        radius: 2.0,
    };
    let r = lens.radius;
    let focus = lens.centre + DVec3::new(0.0, 0.0, r);
    let settings = RaySettings::for_scale(r, 1e-9);
    for offset in [0.05, 0.2, 0.4, 0.6, 0.8, 0.95] {
        for around in [0.0, 1.3, 2.9] {
            let side = DVec3::new(f64::cos(around), f64::sin(around), 0.0) * offset * r;
            let start = lens.centre + side - DVec3::new(0.0, 0.0, 2.0 * r);
            // Trace until the ray has been inside and is outside again.
            let mut inside = false;
            let mut exit = None;
            trace(&lens, start, DVec3::Z, 6.0 * r, &settings, |p| {
                let d = (p.position - lens.centre).length();
                if d < r {
                    inside = true;
                } else if inside {
                    exit = Some(*p);
                    return false;
                }
                true
            })
            .unwrap();
            let p = exit.expect("the ray leaves the lens");
            // Outside the lens the ray is straight: back along it to the rim.
            let q = p.position - lens.centre;
            let bq = q.dot(p.direction);
            // The nearer of the two crossings behind p.
            let t = -bq + (bq * bq - (q.length_squared() - r * r)).sqrt();
            let rim = p.position + p.direction * t;
            let miss = (rim - focus).length();
            assert!(
                miss < 1e-3 * r,
                "offset {offset} R: the ray leaves the rim {miss:.2e} from the focus"
            );
        }
    }
}

/// The ray tube carried by the variational equations is the derivative of the ray family:
/// against central differences of neighbouring rays traced to the same arc length through
/// a Luneburg lens, entering it across its rim, where ∇η jumps and the tube must take the
/// jump (both traced at 1e-12 per unit length: the differences are good to about
/// 1e-12/δ + δ² ≈ 1e-6 relative, the assertion's 1e-5 leaves room; without the rim's
/// jump the tube is off by tens of percent).
#[test]
fn the_ray_tube_is_the_derivative_of_neighbouring_rays() {
    use lucent_optics::eikonal::{Tube, trace_tube};
    let lens = Luneburg {
        centre: DVec3::ZERO,
        radius: 1.0,
    };
    let settings = RaySettings::for_scale(1.0, 1e-12);
    // From outside the lens through its rim, where ∇η jumps, to inside it.
    let length = 1.9;
    let start = |a: f64, b: f64| DVec3::new(0.3 + a, -0.2 + b, -1.3);
    let end = |a: f64, b: f64| {
        trace(&lens, start(a, b), DVec3::Z, length, &settings, |_| true)
            .unwrap()
            .position
    };
    let eta0 = lens.eta(start(0.0, 0.0));
    let g = lens.gradient(start(0.0, 0.0));
    // Rays start on the plane z = −1.3 (outside the lens) with v = η d: ∂v/∂aᵢ = d (∇η·eᵢ).
    let tube = Tube {
        dx: [DVec3::X, DVec3::Y],
        dv: [DVec3::Z * g.x, DVec3::Z * g.y],
    };
    let traced = trace_tube(
        &lens,
        start(0.0, 0.0),
        DVec3::Z,
        tube,
        length,
        &settings,
        |_| true,
    )
    .unwrap();
    assert!(
        eta0 == 1.0 && traced.position.length() < 0.95,
        "from outside the rim to inside"
    );
    let delta = 1e-4;
    let fd = [
        (end(delta, 0.0) - end(-delta, 0.0)) / (2.0 * delta),
        (end(0.0, delta) - end(0.0, -delta)) / (2.0 * delta),
    ];
    for i in 0..2 {
        let err = (traced.tube.dx[i] - fd[i]).length() / fd[i].length();
        assert!(
            err < 1e-5,
            "∂x/∂a{i}: tube {:?}, differences {:?}",
            traced.tube.dx[i],
            fd[i]
        );
    }
    // Converging: the lens shrinks the tube's cross-section on its way to the focus.
    assert!(traced.tube.cross_section(traced.direction).abs() < 0.9);
}
