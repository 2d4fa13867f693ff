//! The `--light` and `--sky` values: parsed into [`Light`]s and validated by the library
//! ([`Light::validate`]).

use antiradiance::scene::lights::Light;
use glam::DVec3;

/// Parses `--light` values: `point:X,Y,Z:R,G,B`, `spot:X,Y,Z:DX,DY,DZ:INNER,OUTER:R,G,B`
/// (cone half-angles in degrees, the direction the spot points), `sun:DX,DY,DZ:R,G,B` (the
/// direction the light travels). Colours are radiometric (W/sr for point and spot, W/m^2 for
/// the sun).
pub fn parse_light(text: &str) -> std::result::Result<Light, String> {
    let parts: Vec<&str> = text.split(':').collect();
    let numbers = |s: &str, n: usize, what: &str| -> std::result::Result<Vec<f64>, String> {
        let v: Vec<f64> = s
            .split(',')
            .map(|w| w.trim().parse::<f64>())
            .collect::<std::result::Result<_, _>>()
            .map_err(|_| format!("'{s}' in {what} is not {n} comma-separated numbers"))?;
        if v.len() != n || v.iter().any(|x| !x.is_finite()) {
            return Err(format!("'{s}' in {what} is not {n} finite numbers"));
        }
        Ok(v)
    };
    let v3 = |v: Vec<f64>| DVec3::new(v[0], v[1], v[2]);
    let rgb = |v: Vec<f64>| [v[0], v[1], v[2]];
    let light = match parts.as_slice() {
        ["point", p, c] => Light::Point {
            position: v3(numbers(p, 3, "the position")?),
            intensity: rgb(numbers(c, 3, "the colour")?),
        },
        ["spot", p, d, cone, c] => {
            let angles = numbers(cone, 2, "the cone angles")?;
            Light::Spot {
                position: v3(numbers(p, 3, "the position")?),
                direction: v3(numbers(d, 3, "the direction")?),
                intensity: rgb(numbers(c, 3, "the colour")?),
                inner: angles[0].to_radians(),
                outer: angles[1].to_radians(),
            }
        }
        ["sun", d, c] => Light::Sun {
            direction: v3(numbers(d, 3, "the direction")?),
            irradiance: rgb(numbers(c, 3, "the colour")?),
        },
        _ => {
            return Err(format!(
                "'{text}' is not point:X,Y,Z:R,G,B, spot:X,Y,Z:DX,DY,DZ:INNER,OUTER:R,G,B or sun:DX,DY,DZ:R,G,B"
            ))
        }
    };
    light.validate("--light").map_err(|e| e.to_string())?;
    Ok(light)
}

/// Parses `--sky R,G,B` (radiance, W/(m^2 sr)).
pub fn parse_sky(text: &str) -> std::result::Result<Light, String> {
    let v: Vec<f64> = text
        .split(',')
        .map(|w| w.trim().parse::<f64>())
        .collect::<std::result::Result<_, _>>()
        .map_err(|_| format!("'{text}' is not R,G,B"))?;
    if v.len() != 3 {
        return Err(format!("'{text}' is not R,G,B"));
    }
    let light = Light::Sky {
        radiance: [v[0], v[1], v[2]],
    };
    light.validate("--sky").map_err(|e| e.to_string())?;
    Ok(light)
}
