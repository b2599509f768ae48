//! The local geomagnetic field from the World Magnetic Model: total intensity, dip
//! (inclination) and declination at a place and date, used as the magnetometer's reference
//! magnitude and to check a fitted radius.
//!
//! The synthesis is the maintained `world_magnetic_model` crate (NOAA/BGS WMM, spherical
//! harmonics to degree 12; it bundles the WMM2020 and WMM2025 coefficient sets and picks the
//! one in force for the date, so dates from 2020-01-01 to 2029-12-31 are covered).

use std::str::FromStr;

use world_magnetic_model::uom::si::angle::degree;
use world_magnetic_model::uom::si::f32::{Angle, Length};
use world_magnetic_model::uom::si::length::meter;
use world_magnetic_model::uom::si::magnetic_flux_density::microtesla;
use world_magnetic_model::GeomagneticField;

/// Calendar date type of the model (re-exported so callers need no other crate).
pub use world_magnetic_model::time::{Date, Month};

/// Heights above the WGS 84 ellipsoid the model accepts, metres (WMM validity range).
const HEIGHT_RANGE_M: (f64, f64) = (-1_000.0, 850_000.0);

/// Days from the Julian-day origin to 1970-01-01 (Julian day number of the Unix epoch).
const UNIX_EPOCH_JULIAN_DAY: i64 = 2_440_588;

/// Why a location or a field lookup was refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum GeomagError {
    /// The `--location` text is not `LAT,LON` or `LAT,LON,ALT_M`.
    #[error("location `{text}` is not `LAT,LON` or `LAT,LON,ALT_M` in degrees and metres (e.g. `46.05,14.51,295`)")]
    Syntax {
        /// The text given.
        text: String,
    },
    /// Latitude outside −90…90°.
    #[error("latitude {0}° is outside −90…90°; give the latitude first, north positive")]
    Latitude(f64),
    /// Longitude outside −180…180°.
    #[error("longitude {0}° is outside −180…180°; give east positive, west negative")]
    Longitude(f64),
    /// Height outside the model's range.
    #[error(
        "altitude {0} m is outside the model's range of −1 km to 850 km above the WGS 84 ellipsoid"
    )]
    Altitude(f64),
    /// The date is outside the bundled models.
    #[error("the date {date} is outside the bundled World Magnetic Models (2020-01-01 to 2029-12-31); give the field with --field-ut instead")]
    Date {
        /// The date asked for.
        date: String,
    },
}

/// A place on the WGS 84 ellipsoid.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Location {
    /// Geodetic latitude, degrees, north positive.
    pub latitude_deg: f64,
    /// Longitude, degrees, east positive.
    pub longitude_deg: f64,
    /// Height above the WGS 84 ellipsoid, metres (0 when not given).
    pub altitude_m: f64,
}

impl Location {
    /// A location after checking each coordinate's range.
    pub fn new(
        latitude_deg: f64,
        longitude_deg: f64,
        altitude_m: f64,
    ) -> Result<Self, GeomagError> {
        if !(latitude_deg.is_finite() && (-90.0..=90.0).contains(&latitude_deg)) {
            return Err(GeomagError::Latitude(latitude_deg));
        }
        if !(longitude_deg.is_finite() && (-180.0..=180.0).contains(&longitude_deg)) {
            return Err(GeomagError::Longitude(longitude_deg));
        }
        if !(altitude_m.is_finite() && (HEIGHT_RANGE_M.0..=HEIGHT_RANGE_M.1).contains(&altitude_m))
        {
            return Err(GeomagError::Altitude(altitude_m));
        }
        Ok(Self {
            latitude_deg,
            longitude_deg,
            altitude_m,
        })
    }
}

impl FromStr for Location {
    type Err = GeomagError;

    /// Parses `LAT,LON` or `LAT,LON,ALT_M`.
    fn from_str(text: &str) -> Result<Self, Self::Err> {
        let syntax = || GeomagError::Syntax {
            text: text.to_string(),
        };
        let numbers: Vec<f64> = text
            .split(',')
            .map(|part| part.trim().parse::<f64>())
            .collect::<Result<_, _>>()
            .map_err(|_| syntax())?;
        match numbers.as_slice() {
            [lat, lon] => Self::new(*lat, *lon, 0.0),
            [lat, lon, alt] => Self::new(*lat, *lon, *alt),
            _ => Err(syntax()),
        }
    }
}

/// The modelled main field at a location and date.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct LocalField {
    /// Total intensity `F`, µT.
    pub total_ut: f64,
    /// One-sigma uncertainty of `F` from the WMM error model, µT.
    pub total_uncertainty_ut: f64,
    /// Horizontal intensity `H`, µT.
    pub horizontal_ut: f64,
    /// Inclination (dip) `I`, degrees, positive downward.
    pub inclination_deg: f64,
    /// Declination `D`, degrees, positive east of true north.
    pub declination_deg: f64,
    /// Model used: `"WMM2025"` or `"WMM2020"`.
    pub model: &'static str,
}

/// The date of a Unix time (UTC), as the model takes it.
pub fn date_of_unix_seconds(unix_s: i64) -> Option<Date> {
    let day = i32::try_from(unix_s.div_euclid(86_400) + UNIX_EPOCH_JULIAN_DAY).ok()?;
    Date::from_julian_day(day).ok()
}

/// Today's date (UTC) from the system clock.
pub fn today() -> Option<Date> {
    let now = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .ok()?;
    date_of_unix_seconds(i64::try_from(now.as_secs()).ok()?)
}

/// The field at `location` on `date`.
pub fn local_field(location: &Location, date: Date) -> Result<LocalField, GeomagError> {
    let field = GeomagneticField::new(
        Length::new::<meter>(location.altitude_m as f32),
        Angle::new::<degree>(location.latitude_deg as f32),
        Angle::new::<degree>(location.longitude_deg as f32),
        date,
    )
    .map_err(|error| match error {
        world_magnetic_model::Error::InvalidLatitude => {
            GeomagError::Latitude(location.latitude_deg)
        }
        world_magnetic_model::Error::InvalidLongitude => {
            GeomagError::Longitude(location.longitude_deg)
        }
        world_magnetic_model::Error::HeightOutsideOfValidityRange { .. } => {
            GeomagError::Altitude(location.altitude_m)
        }
        world_magnetic_model::Error::DateOutsideOfValidityRange { .. } => GeomagError::Date {
            date: date.to_string(),
        },
    })?;
    Ok(LocalField {
        total_ut: f64::from(field.f().get::<microtesla>()),
        total_uncertainty_ut: f64::from(field.f_uncertainty().get::<microtesla>()),
        horizontal_ut: f64::from(field.h().get::<microtesla>()),
        inclination_deg: f64::from(field.inclination().get::<degree>()),
        declination_deg: f64::from(field.declination().get::<degree>()),
        model: if date.year() >= 2025 {
            "WMM2025"
        } else {
            "WMM2020"
        },
    })
}

/// The field at `location` today (see [`today`]).
pub fn local_field_today(location: &Location) -> Result<LocalField, GeomagError> {
    let date = today().ok_or_else(|| GeomagError::Date {
        date: "of the system clock".to_string(),
    })?;
    local_field(location, date)
}

/// How a fitted magnetometer radius compares with the modelled field.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct RadiusCheck {
    /// Mean radius of the raw readings (the fitted sphere), µT.
    pub fitted_ut: f64,
    /// Modelled total intensity, µT.
    pub model_ut: f64,
    /// `fitted / model − 1`, percent.
    pub deviation_pct: f64,
    /// Whether the deviation is within [`RADIUS_TOLERANCE_PCT`].
    pub plausible: bool,
}

/// Largest plausible deviation of a raw magnetometer radius from the model, percent: raw
/// sensitivities are specified to about ±10–15 % and indoor fields differ from the main field
/// by several percent, so only larger deviations point at a wrong unit or a disturbed place.
pub const RADIUS_TOLERANCE_PCT: f64 = 20.0;

impl RadiusCheck {
    /// Compare a raw radius in µT with the modelled field.
    pub fn new(fitted_ut: f64, field: &LocalField) -> Self {
        let deviation_pct = (fitted_ut / field.total_ut - 1.0) * 100.0;
        Self {
            fitted_ut,
            model_ut: field.total_ut,
            deviation_pct,
            plausible: deviation_pct.is_finite() && deviation_pct.abs() <= RADIUS_TOLERANCE_PCT,
        }
    }

    /// One sentence for a person.
    pub fn sentence(&self) -> String {
        if self.plausible {
            format!(
                "the raw radius {:.1} µT is within {:.0} % of the modelled field {:.1} µT ({:+.1} %)",
                self.fitted_ut, RADIUS_TOLERANCE_PCT, self.model_ut, self.deviation_pct
            )
        } else {
            format!(
                "the raw radius {:.1} µT differs from the modelled field {:.1} µT by {:+.0} %: check the magnetometer unit (--mag-unit) and move away from steel and magnets",
                self.fitted_ut, self.model_ut, self.deviation_pct
            )
        }
    }
}
