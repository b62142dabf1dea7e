//! Radiometric and photometric conversions.

/// Planck constant, J·s.
pub const PLANCK_J_S: f64 = 6.626_070_15e-34;
/// Speed of light, m/s.
pub const SPEED_OF_LIGHT_M_S: f64 = 299_792_458.0;
/// Maximum luminous efficacy of photopic vision, lm/W (CIE: 683 lm/W at 555 nm).
pub const LUMINOUS_EFFICACY_LM_PER_W: f64 = 683.0;

/// Energy of one photon at `lambda_nm`, in joules.
pub fn photon_energy_j(lambda_nm: f64) -> f64 {
    PLANCK_J_S * SPEED_OF_LIGHT_M_S / (lambda_nm * 1e-9)
}

/// Convert an energy quantity (W/…/nm) to a photon quantity (photons/s/…/nm).
pub fn energy_to_photons(value_w: f64, lambda_nm: f64) -> f64 {
    value_w / photon_energy_j(lambda_nm)
}

/// Convert a photon quantity back to an energy quantity.
pub fn photons_to_energy(value_photons: f64, lambda_nm: f64) -> f64 {
    value_photons * photon_energy_j(lambda_nm)
}

/// Luminance (cd/m²) of a spectral radiance W/(sr·m²·nm), or illuminance (lux)
/// of a spectral irradiance W/(m²·nm): 683 lm/W · ∫ L(λ) ȳ(λ) dλ.
pub fn luminance(spd: &super::Spectrum, grid: &super::WavelengthGrid) -> f64 {
    let y = &super::library::cie1931_cmfs()[1];
    LUMINOUS_EFFICACY_LM_PER_W * spd.integrate_product(y, grid)
}

#[cfg(test)]
mod tests {
    use super::*;
    #[test]
    fn photon_energy_at_555nm() {
        // hc/λ = 3.579e-19 J at 555 nm
        assert!((photon_energy_j(555.0) - 3.5793e-19).abs() < 1e-22);
        // 10¹⁹ photons at 500 nm carry 10¹⁹·hc/λ = 3.972891714 J (exact SI
        // constants), and the two conversions are each other's inverse.
        let e = photons_to_energy(1e19, 500.0);
        assert!((e - 3.972_891_714).abs() < 1e-9, "{e}");
        let p = energy_to_photons(2.5, 500.0);
        assert!((p - 2.5e19 / 3.972_891_714).abs() < 1e-9 * p, "{p}");
        assert!((photons_to_energy(p, 500.0) - 2.5).abs() < 1e-12);
    }
    #[test]
    fn luminance_of_flat_spectrum() {
        // ∫ȳ dλ over the CIE 1931 table is ≈106.86 nm; 1 W/(sr·m²·nm) flat → 683·106.86 cd/m².
        let s = crate::spectrum::Spectrum::constant("one", 1.0);
        let g = crate::spectrum::WavelengthGrid::new(380.0, 780.0, 5.0).unwrap();
        let l = luminance(&s, &g);
        assert!((l / 683.0 - 106.86).abs() < 0.1, "{l}");
    }
}
