//! Scatter distributions (docs/contract.md "Job", `D`): validation against the parameter they feed,
//! random draws (rand_distr) and inverse CDFs (for Latin hypercube sampling).

use crate::error::{FieldError, Pointer, shown};
use crate::scenario::{MAX_MAGNITUDE, MIN_MAGNITUDE};
use rand::RngExt;
use rand::distr::{Distribution as _, Open01};
use rand_distr::{LogNormal, Normal, Triangular, Weibull};
use serde::{Deserialize, Serialize};

/// Truncated distributions (normal, lognormal, Weibull) are drawn by rejection; validation requires
/// at least this acceptance probability, so that [`MAX_REJECTIONS`] failures in a row have
/// probability below `0.95^1000 = 5e-23` (the draw is then clamped into the window, which never
/// happens in practice).
pub const MIN_ACCEPTANCE: f64 = 0.05;
/// See [`MIN_ACCEPTANCE`].
pub const MAX_REJECTIONS: u32 = 1000;

/// The farthest standard score of any draw: [`Distribution::at_normal`] (rare events, correlated
/// draws) holds its `z` within it, where `Phi(-z)` is still a normal number; the ziggurat's normals
/// and the probabilities of (0, 1) that random and stratified draws invert stay well inside it.
pub const MAX_SCORE: f64 = 37.0;

/// A distribution as the user writes it.
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
// Read by its own `Deserialize` (below), so that a fault names its member.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum DistributionSpec {
    /// Always `value`.
    Fixed {
        /// The one value.
        value: f64,
    },
    /// A normal, truncated to `[min, max]`; the window must keep at least 5 % of its mass.
    Normal {
        /// Mean before truncation.
        mean: f64,
        /// Standard deviation before truncation (positive).
        sd: f64,
        /// Lower truncation bound, valid for the parameter; required unless the parameter may take any finite value.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        min: Option<f64>,
        /// Upper truncation bound, above `min` (default: none).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        max: Option<f64>,
    },
    /// A lognormal, optionally truncated to `[min, max]` (the window must keep at least 5 % of its mass).
    Lognormal {
        /// Median before truncation (positive).
        median: f64,
        /// Standard deviation of the logarithm (positive).
        sigma: f64,
        /// Lower truncation bound, valid for the parameter; required where values near 0 are not.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        min: Option<f64>,
        /// Upper truncation bound, above `min` (default: none).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        max: Option<f64>,
    },
    /// Uniform on `[min, max]`.
    Uniform {
        /// Lower bound, valid for the parameter.
        min: f64,
        /// Upper bound, above `min`.
        max: f64,
    },
    /// Triangular on `[min, max]` with its peak at `mode`.
    Triangular {
        /// Lower bound, valid for the parameter.
        min: f64,
        /// The most likely value, from `min` to `max`.
        mode: f64,
        /// Upper bound, above `min`.
        max: f64,
    },
    /// A two-parameter Weibull, optionally truncated to `[min, max]` (the window must keep at least 5 % of its mass).
    Weibull {
        /// Scale before truncation (positive).
        scale: f64,
        /// Shape (positive).
        shape: f64,
        /// Lower truncation bound, valid for the parameter; required where values near 0 are not.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        min: Option<f64>,
        /// Upper truncation bound, above `min` (default: none).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        max: Option<f64>,
    },
}

impl DistributionSpec {
    /// The `min` and `max` the spec gives, if any (for a fixed value, neither).
    fn bounds(&self) -> (Option<f64>, Option<f64>) {
        match *self {
            DistributionSpec::Fixed { .. } => (None, None),
            DistributionSpec::Uniform { min, max }
            | DistributionSpec::Triangular { min, max, .. } => (Some(min), Some(max)),
            DistributionSpec::Normal { min, max, .. }
            | DistributionSpec::Lognormal { min, max, .. }
            | DistributionSpec::Weibull { min, max, .. } => (min, max),
        }
    }
}

/// A distribution's kind, the value of its `kind` member.
#[derive(Debug, Clone, Copy, Deserialize)]
#[serde(rename_all = "snake_case")]
enum Kind {
    Fixed,
    Normal,
    Lognormal,
    Uniform,
    Triangular,
    Weibull,
}

impl Kind {
    /// Its members besides `kind`, those it needs first.
    fn members(self) -> (&'static [&'static str], &'static [&'static str]) {
        match self {
            Kind::Fixed => (&["value"], &[]),
            Kind::Normal => (&["mean", "sd"], &["min", "max"]),
            Kind::Lognormal => (&["median", "sigma"], &["min", "max"]),
            Kind::Uniform => (&["min", "max"], &[]),
            Kind::Triangular => (&["min", "mode", "max"], &[]),
            Kind::Weibull => (&["scale", "shape"], &["min", "max"]),
        }
    }

    /// Whether a distribution of this kind has the member `name`.
    fn has(self, name: &str) -> bool {
        let (needed, optional) = self.members();
        needed.contains(&name) || optional.contains(&name)
    }

    /// Whether this kind may go without the member `name` (a truncation bound), which `null`
    /// then leaves out, as the OpenAPI document's `["number", "null"]` says.
    fn may_omit(self, name: &str) -> bool {
        self.members().1.contains(&name)
    }

    /// Its members, `kind` first, as an unknown member's error lists them.
    fn listed(self) -> &'static [&'static str] {
        match self {
            Kind::Fixed => &["kind", "value"],
            Kind::Normal => &["kind", "mean", "sd", "min", "max"],
            Kind::Lognormal => &["kind", "median", "sigma", "min", "max"],
            Kind::Uniform => &["kind", "min", "max"],
            Kind::Triangular => &["kind", "min", "mode", "max"],
            Kind::Weibull => &["kind", "scale", "shape", "min", "max"],
        }
    }
}

/// The members positive whatever parameter the distribution feeds (`Faults::positive`); the
/// OpenAPI document states each as its member's range.
pub const POSITIVE_MEMBERS: [&str; 5] = ["sd", "median", "sigma", "scale", "shape"];

/// Every number member of any kind of distribution.
const NUMBER_MEMBERS: [&str; 10] = [
    "value", "mean", "sd", "median", "sigma", "min", "max", "mode", "scale", "shape",
];

/// Every member of any kind of distribution, as an error lists them before `kind` is known.
const ANY_MEMBER: [&str; 11] = [
    "kind", "value", "mean", "sd", "median", "sigma", "min", "max", "mode", "scale", "shape",
];

/// serde's internally tagged enums read an object whole before they know its variant, so a fault
/// in `mean` was named at the distribution (a probe); this reads it member by member, so that a
/// wrong type or a member its kind does not have is named where it is.
impl<'de> Deserialize<'de> for DistributionSpec {
    fn deserialize<D: serde::Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        deserializer.deserialize_map(SpecVisitor)
    }
}

struct SpecVisitor;

impl<'de> serde::de::Visitor<'de> for SpecVisitor {
    type Value = DistributionSpec;

    fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
        f.write_str("a distribution: an object with its `kind` and its numbers")
    }

    fn visit_map<A: serde::de::MapAccess<'de>>(self, mut map: A) -> Result<Self::Value, A::Error> {
        use serde::de::Error;
        let mut kind: Option<Kind> = None;
        // Each member as given: absent, `null` (read before `kind`), or a number.
        let mut numbers = [None::<Option<f64>>; NUMBER_MEMBERS.len()];
        while let Some(name) = map.next_key::<String>()? {
            if name == "kind" {
                kind = Some(map.next_value()?);
                continue;
            }
            let slot = NUMBER_MEMBERS.iter().position(|member| *member == name);
            match (slot, kind) {
                (Some(slot), None) => numbers[slot] = Some(map.next_value()?),
                (Some(slot), Some(kind)) if kind.may_omit(&name) => {
                    numbers[slot] = Some(map.next_value()?);
                }
                (Some(slot), Some(kind)) if kind.has(&name) => {
                    numbers[slot] = Some(Some(map.next_value()?));
                }
                // Named at the member itself, once the kind is known.
                (_, Some(kind)) => {
                    map.next_value_seed(NotAMember(name, kind.listed()))?;
                }
                (None, None) => map.next_value_seed(NotAMember(name, &ANY_MEMBER))?,
            }
        }
        let kind = kind.ok_or_else(|| A::Error::missing_field("kind"))?;
        let written = |name: &str| {
            let slot = NUMBER_MEMBERS.iter().position(|member| *member == name);
            slot.and_then(|slot| numbers[slot])
        };
        let given = |name: &str| written(name).flatten();
        // A member read before `kind` that this kind does not have (members come in their
        // names' order from a document read whole, so only `extra`-like names precede `kind`).
        if let Some(name) = NUMBER_MEMBERS
            .iter()
            .find(|name| written(name).is_some() && !kind.has(name))
        {
            return Err(A::Error::unknown_field(name, kind.listed()));
        }
        let needed = |name: &'static str| match written(name) {
            Some(Some(value)) => Ok(value),
            Some(None) => Err(A::Error::custom(format_args!(
                "`{name}`: invalid type: null, expected a number"
            ))),
            None => Err(A::Error::missing_field(name)),
        };
        Ok(match kind {
            Kind::Fixed => DistributionSpec::Fixed {
                value: needed("value")?,
            },
            Kind::Normal => DistributionSpec::Normal {
                mean: needed("mean")?,
                sd: needed("sd")?,
                min: given("min"),
                max: given("max"),
            },
            Kind::Lognormal => DistributionSpec::Lognormal {
                median: needed("median")?,
                sigma: needed("sigma")?,
                min: given("min"),
                max: given("max"),
            },
            Kind::Uniform => DistributionSpec::Uniform {
                min: needed("min")?,
                max: needed("max")?,
            },
            Kind::Triangular => DistributionSpec::Triangular {
                min: needed("min")?,
                mode: needed("mode")?,
                max: needed("max")?,
            },
            Kind::Weibull => DistributionSpec::Weibull {
                scale: needed("scale")?,
                shape: needed("shape")?,
                min: given("min"),
                max: given("max"),
            },
        })
    }
}

/// A member a distribution's kind does not have: its error is raised reading its value, so that
/// it is named at the member.
struct NotAMember(String, &'static [&'static str]);

impl<'de> serde::de::DeserializeSeed<'de> for NotAMember {
    type Value = ();

    fn deserialize<D: serde::Deserializer<'de>>(self, _: D) -> Result<Self::Value, D::Error> {
        Err(serde::de::Error::unknown_field(&self.0, self.1))
    }
}

/// The values a parameter may take: above `lower` (or at it, when `inclusive`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Domain {
    pub lower: f64,
    pub inclusive: bool,
}

impl Domain {
    pub const POSITIVE: Domain = Domain {
        lower: 0.0,
        inclusive: false,
    };
    pub const NON_NEGATIVE: Domain = Domain {
        lower: 0.0,
        inclusive: true,
    };
    /// Any finite value (a coefficient that may be negative).
    pub const FINITE: Domain = Domain {
        lower: f64::NEG_INFINITY,
        inclusive: false,
    };

    pub fn contains(&self, x: f64) -> bool {
        x.is_finite() && (x > self.lower || (self.inclusive && x == self.lower))
    }

    fn describe(&self) -> String {
        match (self.lower, self.inclusive) {
            (f64::NEG_INFINITY, _) => "finite".to_owned(),
            (0.0, false) => "positive".to_owned(),
            (0.0, true) => "non-negative".to_owned(),
            (lower, true) => format!("at least {}", shown(lower)),
            (lower, false) => format!("above {}", shown(lower)),
        }
    }

    /// The `min` to suggest for truncating a distribution that reaches below the domain.
    fn suggested_min(&self) -> String {
        if self.inclusive {
            format!("\"min\": {}", shown(self.lower))
        } else {
            format!("a \"min\" above {}", shown(self.lower))
        }
    }
}

/// The window `[min, max]` a distribution is truncated to, with the probabilities of its bounds
/// under the untruncated distribution. Untruncated, it is the whole support (`cdf_min` 0 and
/// `cdf_max` 1), so that draws and quantiles are those of the plain distribution, bit for bit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Window {
    pub min: f64,
    pub max: f64,
    pub cdf_min: f64,
    pub cdf_max: f64,
}

impl Window {
    /// A draw from `draw` inside the window, by rejection; `rejections` counts the draws that fell
    /// outside it.
    #[inline(always)]
    fn sample(&self, mut draw: impl FnMut() -> f64, rejections: &mut u64) -> f64 {
        for _ in 0..MAX_REJECTIONS {
            let x = draw();
            if x >= self.min && x <= self.max {
                return x;
            }
            *rejections += 1;
        }
        draw().clamp(self.min, self.max)
    }

    /// The standard score, under the untruncated normal of a normal or lognormal, of the
    /// truncated distribution's probability `Phi(z)`, its window ending at standard score
    /// `max_score`: `z` itself without truncation; below the median through `Phi(z)`, above it
    /// through the survival probability `Phi(-z)`, each precise in its own tail.
    fn score(&self, z: f64, max_score: f64) -> f64 {
        if self.cdf_min == 0.0 && self.cdf_max == 1.0 {
            return z;
        }
        let mass = self.cdf_max - self.cdf_min;
        if z <= 0.0 {
            standard_normal_quantile(self.cdf_min + standard_normal_cdf(z) * mass)
        } else {
            let above = standard_normal_cdf(-max_score);
            -standard_normal_quantile(above + standard_normal_cdf(-z) * mass)
        }
    }

    /// The untruncated probability of the truncated distribution's probability `u`.
    fn probability(&self, u: f64) -> f64 {
        self.cdf_min + u * (self.cdf_max - self.cdf_min)
    }
}

/// A validated distribution, ready to draw from.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Distribution {
    Fixed(f64),
    Normal {
        normal: Normal<f64>,
        mean: f64,
        sd: f64,
        window: Window,
    },
    Lognormal {
        lognormal: LogNormal<f64>,
        median: f64,
        sigma: f64,
        window: Window,
    },
    Uniform {
        min: f64,
        max: f64,
    },
    Triangular {
        triangular: Triangular<f64>,
        min: f64,
        mode: f64,
        max: f64,
    },
    Weibull {
        weibull: Weibull<f64>,
        scale: f64,
        shape: f64,
        window: Window,
    },
}

impl Distribution {
    /// Checks that every value the distribution can produce lies in `domain`, naming the field at fault.
    pub fn new(
        spec: &DistributionSpec,
        domain: Domain,
        at: &Pointer,
    ) -> Result<Self, Vec<FieldError>> {
        let mut faults = Faults {
            at,
            errors: Vec::new(),
        };
        let distribution = match *spec {
            DistributionSpec::Fixed { value } => {
                faults.lowest_in("value", value, domain);
                Some(Distribution::Fixed(value))
            }
            DistributionSpec::Normal { mean, sd, min, max } => {
                faults.normal(mean, sd, min, max, domain)
            }
            DistributionSpec::Lognormal {
                median,
                sigma,
                min,
                max,
            } => faults.lognormal(median, sigma, min, max, domain),
            DistributionSpec::Uniform { min, max } => {
                faults.lowest_in("min", min, domain);
                faults.max_above_min(max, min);
                Some(Distribution::Uniform { min, max })
            }
            DistributionSpec::Triangular { min, mode, max } => {
                faults.triangular(min, mode, max, domain)
            }
            DistributionSpec::Weibull {
                scale,
                shape,
                min,
                max,
            } => faults.weibull(scale, shape, min, max, domain),
        };
        if let Some(distribution) = &distribution
            && faults.errors.is_empty()
        {
            faults.within_magnitude(distribution, spec, domain);
            if domain.lower >= 0.0 {
                faults.above_least_magnitude(distribution, spec, domain);
            }
            if faults.errors.is_empty() && domain.lower >= 0.0 {
                faults.reaches_least_magnitude(distribution, spec);
            }
        }
        match distribution {
            Some(distribution) if faults.errors.is_empty() => Ok(distribution),
            _ => Err(faults.errors),
        }
    }

    /// One random draw.
    #[inline]
    pub fn sample<R: rand::Rng + ?Sized>(&self, rng: &mut R) -> f64 {
        self.sample_counting(rng, &mut 0)
    }

    /// One random draw; a truncated distribution adds to `rejections` the draws it made outside
    /// its window (diagnostics count them).
    #[inline(always)]
    pub fn sample_counting<R: rand::Rng + ?Sized>(&self, rng: &mut R, rejections: &mut u64) -> f64 {
        match self {
            Distribution::Fixed(value) => *value,
            Distribution::Normal { normal, window, .. } => {
                window.sample(|| normal.sample(rng), rejections)
            }
            Distribution::Lognormal {
                lognormal, window, ..
            } => window.sample(|| lognormal.sample(rng), rejections),
            Distribution::Uniform { min, max } => min + (max - min) * rng.random::<f64>(),
            Distribution::Triangular { triangular, .. } => triangular.sample(rng),
            Distribution::Weibull {
                weibull, window, ..
            } => window.sample(|| weibull.sample(rng), rejections),
        }
    }

    /// The value at probability `u` in (0, 1): the inverse CDF, for stratified (LHS) and
    /// correlated draws. A truncated distribution is inverted inside its window, so no rejection
    /// is needed.
    pub fn quantile(&self, u: f64) -> f64 {
        match *self {
            Distribution::Fixed(value) => value,
            Distribution::Normal {
                mean, sd, window, ..
            } => (mean + sd * standard_normal_quantile(window.probability(u)))
                .clamp(window.min, window.max),
            Distribution::Lognormal {
                median,
                sigma,
                window,
                ..
            } => (median * (sigma * standard_normal_quantile(window.probability(u))).exp())
                .clamp(window.min, window.max),
            Distribution::Uniform { min, max } => min + u * (max - min),
            Distribution::Triangular { min, mode, max, .. } => {
                let split = (mode - min) / (max - min);
                if u < split {
                    min + (u * (max - min) * (mode - min)).sqrt()
                } else {
                    max - ((1.0 - u) * (max - min) * (max - mode)).sqrt()
                }
            }
            Distribution::Weibull {
                scale,
                shape,
                window,
                ..
            } => (scale * (-(-window.probability(u)).ln_1p()).powf(1.0 / shape))
                .clamp(window.min, window.max),
        }
    }

    /// The value at standard normal `z`: `quantile(Phi(z))`, without `Phi`'s rounding in the
    /// upper tail. `Phi(z)` rounds to 1 beyond about 8.1 standard deviations, where every `z`
    /// would map to one value; rare events read inputs out to 11.5 (`montecarlo::rare`). A
    /// normal or lognormal without truncation maps `z` itself (`mean + sd z`, `median
    /// exp(sigma z)`); a truncated one, a Weibull and a triangular's upper side go through the
    /// survival probability `Phi(-z)`, which keeps its relative precision. `z` is held within
    /// +-[`MAX_SCORE`].
    pub fn at_normal(&self, z: f64) -> f64 {
        let z = z.clamp(-MAX_SCORE, MAX_SCORE);
        let through_phi = |z: f64| {
            self.quantile(standard_normal_cdf(z).clamp(f64::MIN_POSITIVE, 1.0 - f64::EPSILON))
        };
        match *self {
            Distribution::Fixed(value) => value,
            Distribution::Normal {
                mean, sd, window, ..
            } => {
                let score = window.score(z, (window.max - mean) / sd);
                (mean + sd * score).clamp(window.min, window.max)
            }
            Distribution::Lognormal {
                median,
                sigma,
                window,
                ..
            } => {
                let score = window.score(z, (window.max / median).ln() / sigma);
                (median * (sigma * score).exp()).clamp(window.min, window.max)
            }
            _ if z <= 0.0 => through_phi(z),
            Distribution::Weibull {
                scale,
                shape,
                window,
                ..
            } => {
                // The survival exp(-(x / scale)^shape) above the window, then the window's share.
                let above = (-(window.max / scale).powf(shape)).exp();
                let survival = above + standard_normal_cdf(-z) * (window.cdf_max - window.cdf_min);
                (scale * (-survival.ln()).powf(1.0 / shape)).clamp(window.min, window.max)
            }
            Distribution::Triangular { min, mode, max, .. } => {
                let upper = standard_normal_cdf(-z);
                if upper < (max - mode) / (max - min) {
                    max - (upper * (max - min) * (max - mode)).sqrt()
                } else {
                    through_phi(z)
                }
            }
            Distribution::Uniform { min, max } => max - standard_normal_cdf(-z) * (max - min),
        }
    }

    /// A draw at a random point of stratum `stratum` of `strata` equal-probability strata.
    pub fn stratified<R: rand::Rng + ?Sized>(&self, stratum: u32, strata: u32, rng: &mut R) -> f64 {
        self.quantile(stratified_probability(stratum, strata, rng))
    }
}

/// A random probability in stratum `stratum` of `strata` equal strata of (0, 1).
pub fn stratified_probability<R: rand::Rng + ?Sized>(
    stratum: u32,
    strata: u32,
    rng: &mut R,
) -> f64 {
    let offset: f64 = rng.sample(Open01);
    (f64::from(stratum) + offset) / f64::from(strata)
}

/// Each kind's parameters checked and, when they hold, its distribution (`None` otherwise).
impl Faults<'_> {
    fn normal(
        &mut self,
        mean: f64,
        sd: f64,
        min: Option<f64>,
        max: Option<f64>,
        domain: Domain,
    ) -> Option<Distribution> {
        if !mean.is_finite() {
            self.fail("mean", "must be a finite number".into());
        }
        self.positive("sd", sd);
        let support = Support {
            name: format!("normal(mean {}, sd {})", shown(mean), shown(sd)),
            lowest: f64::NEG_INFINITY,
            missing_min: "min",
        };
        let window = self.window(&support, min, max, domain, |x| {
            standard_normal_cdf((x - mean) / sd)
        });
        let normal = Normal::new(mean, sd).ok()?;
        Some(Distribution::Normal {
            normal,
            mean,
            sd,
            window,
        })
    }

    fn lognormal(
        &mut self,
        median: f64,
        sigma: f64,
        min: Option<f64>,
        max: Option<f64>,
        domain: Domain,
    ) -> Option<Distribution> {
        self.positive("median", median);
        self.positive("sigma", sigma);
        let support = Support {
            name: format!(
                "lognormal(median {}, sigma {})",
                shown(median),
                shown(sigma)
            ),
            lowest: 0.0,
            missing_min: "kind",
        };
        let window = self.window(&support, min, max, domain, |x| {
            standard_normal_cdf((x / median).ln() / sigma)
        });
        let lognormal = LogNormal::new(median.ln(), sigma).ok()?;
        Some(Distribution::Lognormal {
            lognormal,
            median,
            sigma,
            window,
        })
    }

    fn triangular(
        &mut self,
        min: f64,
        mode: f64,
        max: f64,
        domain: Domain,
    ) -> Option<Distribution> {
        self.lowest_in("min", min, domain);
        self.max_above_min(max, min);
        if !(mode >= min && mode <= max) {
            self.fail(
                "mode",
                format!("must lie in [min, max], got {}", shown(mode)),
            );
        }
        let triangular = Triangular::new(min, max, mode).ok()?;
        Some(Distribution::Triangular {
            triangular,
            min,
            mode,
            max,
        })
    }

    fn weibull(
        &mut self,
        scale: f64,
        shape: f64,
        min: Option<f64>,
        max: Option<f64>,
        domain: Domain,
    ) -> Option<Distribution> {
        self.positive("scale", scale);
        self.positive("shape", shape);
        let support = Support {
            name: format!("Weibull(scale {}, shape {})", shown(scale), shown(shape)),
            lowest: 0.0,
            missing_min: "kind",
        };
        let window = self.window(&support, min, max, domain, |x| {
            -(-(x / scale).powf(shape)).exp_m1()
        });
        let weibull = Weibull::new(scale, shape).ok()?;
        Some(Distribution::Weibull {
            weibull,
            scale,
            shape,
            window,
        })
    }
}

/// The errors found in one distribution, each below its pointer.
struct Faults<'a> {
    at: &'a Pointer,
    errors: Vec<FieldError>,
}

impl Faults<'_> {
    fn fail(&mut self, field: &str, detail: String) {
        self.errors.push(FieldError {
            pointer: self.at.child(field).to_string(),
            detail,
        });
    }

    fn positive(&mut self, field: &str, value: f64) {
        debug_assert!(POSITIVE_MEMBERS.contains(&field), "{field}");
        if !(value.is_finite() && value > 0.0) {
            self.fail(field, format!("must be positive, got {}", shown(value)));
        }
    }

    /// The lowest value the distribution can produce must be in the parameter's domain.
    fn lowest_in(&mut self, field: &str, value: f64, domain: Domain) {
        if !domain.contains(value) {
            self.fail(
                field,
                format!(
                    "must be {} for this parameter, got {}",
                    domain.describe(),
                    shown(value)
                ),
            );
        }
    }

    /// Every value the distribution can produce within a scenario's magnitudes: its `max`, or
    /// without one its value at the farthest score of any draw ([`MAX_SCORE`]), at most
    /// [`MAX_MAGNITUDE`], and for a domain without a lower end its `min` (or value at `-MAX_SCORE`)
    /// at least the negative. An untruncated distribution that reaches beyond is told to add a
    /// `max` (or `min`), as one that reaches below its domain is.
    fn within_magnitude(
        &mut self,
        distribution: &Distribution,
        spec: &DistributionSpec,
        domain: Domain,
    ) {
        let (min, max) = spec.bounds();
        let ends = [
            (1.0, "max", max, "at most", "above", true),
            (
                -1.0,
                "min",
                min,
                "at least",
                "below",
                domain.lower < -MAX_MAGNITUDE,
            ),
        ];
        for (sign, field, given, within, beyond, checked) in ends {
            let reach = given.unwrap_or_else(|| distribution.at_normal(sign * MAX_SCORE));
            if !checked || (reach.is_finite() && sign * reach <= MAX_MAGNITUDE) {
                continue;
            }
            let limit = format!("{:e}", sign * MAX_MAGNITUDE);
            let detail =
                |got: f64| format!("must be {within} {limit} for this parameter, got {got:e}");
            match (spec, given) {
                (DistributionSpec::Fixed { value }, _) => self.fail("value", detail(*value)),
                (_, Some(bound)) => self.fail(field, detail(bound)),
                (_, None) => self.fail(
                    field,
                    format!(
                        "this distribution reaches {reach:e} at {} standard deviations, {beyond} \
                         the {limit} this parameter may take; add a \"{field}\" of {within} \
                         {limit} to truncate it",
                        sign * MAX_SCORE
                    ),
                ),
            }
        }
    }

    /// Every positive value the distribution can draw at least [`MIN_MAGNITUDE`], as a scenario's
    /// own values must be: its fixed value or `min` (a uniform's or triangular's lower end) zero or
    /// from there, and, without a `min`, a lognormal's value at `-MAX_SCORE` and a Weibull's scale.
    /// The lower tail of one from 0 that reaches above (a uniform's first draws above 0, a
    /// Weibull's tail) is left to its draws (docs/model.md section 9).
    fn above_least_magnitude(
        &mut self,
        distribution: &Distribution,
        spec: &DistributionSpec,
        domain: Domain,
    ) {
        let tiny = |value: f64| value > 0.0 && value < MIN_MAGNITUDE;
        let (min, _) = spec.bounds();
        let (field, lowest, reached) = match (spec, min) {
            (DistributionSpec::Fixed { value }, _) => ("value", *value, false),
            (_, Some(min)) => ("min", min, false),
            (DistributionSpec::Lognormal { .. }, None) => {
                ("min", distribution.at_normal(-MAX_SCORE), true)
            }
            (DistributionSpec::Weibull { scale, .. }, None) => ("scale", *scale, false),
            _ => return,
        };
        if !tiny(lowest) {
            return;
        }
        let detail = if reached {
            format!(
                "this distribution reaches {lowest:e} at {} standard deviations, below the \
                 {MIN_MAGNITUDE:e} a positive value of this parameter may take; add a \"min\" of \
                 at least {MIN_MAGNITUDE:e} to truncate it",
                -MAX_SCORE
            )
        } else {
            // 0 only where the parameter and the field take it (a Weibull's scale never does).
            let zero = if domain.inclusive && field != "scale" {
                "0 or "
            } else {
                ""
            };
            format!(
                "must be {zero}at least {MIN_MAGNITUDE:e} (the supported range), got {lowest:e}"
            )
        };
        self.fail(field, detail);
    }

    /// From 0 (a lower end of 0 or none), the distribution's upper end: `max`, or its value at
    /// `MAX_SCORE`, at least [`MIN_MAGNITUDE`], else every positive value it draws is below.
    fn reaches_least_magnitude(&mut self, distribution: &Distribution, spec: &DistributionSpec) {
        let (_, max) = spec.bounds();
        let highest = max.unwrap_or_else(|| distribution.at_normal(MAX_SCORE));
        if matches!(spec, DistributionSpec::Fixed { .. })
            || !(highest > 0.0 && highest < MIN_MAGNITUDE)
        {
            return;
        }
        let field = match (spec, max) {
            (_, Some(_)) => "max",
            (DistributionSpec::Lognormal { .. }, None) => "median",
            (DistributionSpec::Weibull { .. }, None) => "scale",
            _ => "mean",
        };
        self.fail(
            field,
            format!(
                "every positive value this distribution draws is below the {MIN_MAGNITUDE:e} a \
                 non-zero value of this parameter must reach (it reaches at most {highest:e})"
            ),
        );
    }

    fn max_above_min(&mut self, max: f64, min: f64) {
        if !(max.is_finite() && max > min) {
            self.fail(
                "max",
                format!("must be finite and above min, got {}", shown(max)),
            );
        }
    }

    /// The truncation window of a distribution over `support`: `min` and `max` as given, else the
    /// support's own ends. A support reaching below `domain` needs a `min`, which the error
    /// suggests when the distribution's own parameters hold (a normal of sd 0 is refused for its
    /// sd, not told to add a `min` its values would never need); the window must keep at least [`MIN_ACCEPTANCE`] of the mass (`cdf` is the
    /// untruncated CDF).
    fn window(
        &mut self,
        support: &Support,
        min: Option<f64>,
        max: Option<f64>,
        domain: Domain,
        cdf: impl Fn(f64) -> f64,
    ) -> Window {
        // A positive parameter never takes 0, not even a draw that rounds to it: from a support
        // that starts at 0, the window starts at the least positive f64 and such a draw is made
        // again (a Weibull of shape 0.01 rounds 6.6e-4 of its draws to 0; an inertia of 0 ran to
        // a force of NaN, and a kappa of 0 to e1 = 0, found from outside). A window that then
        // keeps too little of the mass is refused as any other.
        let positive = domain.lower == 0.0 && !domain.inclusive;
        let floor = if positive && support.lowest == 0.0 {
            f64::from_bits(1)
        } else {
            support.lowest
        };
        let lo = min.unwrap_or(floor);
        let hi = max.unwrap_or(f64::INFINITY);
        match min {
            Some(lo) => self.lowest_in("min", lo, domain),
            None if domain.lower > support.lowest && self.errors.is_empty() => {
                self.fail(
                    support.missing_min,
                    format!(
                        "a {} reaches below {} (this parameter must be {}); add {} to truncate it",
                        support.name,
                        shown(domain.lower),
                        domain.describe(),
                        domain.suggested_min()
                    ),
                );
            }
            None => {}
        }
        if max.is_some() {
            self.max_above_min(hi, lo);
        }
        let (cdf_min, cdf_max) = match (min, max) {
            (None, None) => (0.0, 1.0),
            _ => (
                if lo <= support.lowest { 0.0 } else { cdf(lo) },
                if hi.is_finite() { cdf(hi) } else { 1.0 },
            ),
        };
        if self.errors.is_empty()
            && (cdf_max - cdf_min < MIN_ACCEPTANCE || cdf_max.is_nan() || cdf_min.is_nan())
        {
            let lower = match min {
                Some(_) => "min",
                None => "the least positive f64 (this parameter takes no 0)",
            };
            self.fail(
                "min",
                format!(
                    "the window [{lower}, max] keeps only {:.3e} of the distribution's mass; at least {MIN_ACCEPTANCE} is needed",
                    cdf_max - cdf_min
                ),
            );
        }
        Window {
            min: lo,
            max: hi,
            cdf_min,
            cdf_max,
        }
    }
}

/// Where a distribution's values lie before truncation, for [`Faults::window`].
struct Support {
    /// The distribution and its parameters, as an error names it.
    name: String,
    /// The lowest value it reaches (approaches).
    lowest: f64,
    /// The field an error about a missing `min` names.
    missing_min: &'static str,
}

/// `Phi(x)`, the standard normal CDF, from libm's `erfc` (accurate in both tails).
pub fn standard_normal_cdf(x: f64) -> f64 {
    0.5 * libm::erfc(-x / std::f64::consts::SQRT_2)
}

/// `Phi^-1(p)` for `p` in (0, 1): Abramowitz & Stegun 26.2.23 (error below 4.5e-4) as a start, then
/// Halley steps on the smaller tail, where `Phi` has full relative accuracy. Each step roughly
/// triples the correct digits, so three leave the result at the rounding level.
pub fn standard_normal_quantile(p: f64) -> f64 {
    if p <= 0.0 {
        return f64::NEG_INFINITY;
    }
    if p >= 1.0 {
        return f64::INFINITY;
    }
    let tail = p.min(1.0 - p);
    let t = (-2.0 * tail.ln()).sqrt();
    let mut x = -(t
        - (2.515_517 + t * (0.802_853 + t * 0.010_328))
            / (1.0 + t * (1.432_788 + t * (0.189_269 + t * 0.001_308))));
    for _ in 0..3 {
        let density = (-0.5 * x * x).exp() / (2.0 * std::f64::consts::PI).sqrt();
        if density == 0.0 {
            break;
        }
        let ratio = (standard_normal_cdf(x) - tail) / density;
        x -= ratio / (1.0 + 0.5 * x * ratio);
    }
    if p > 0.5 { -x } else { x }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    fn parse(json: &str) -> DistributionSpec {
        serde_json::from_str(json).unwrap()
    }

    fn pointers(json: &str, domain: Domain) -> Vec<String> {
        match Distribution::new(&parse(json), domain, &Pointer::root().child("d")) {
            Ok(_) => Vec::new(),
            Err(errors) => errors.into_iter().map(|e| e.pointer).collect(),
        }
    }

    fn distribution(json: &str) -> Distribution {
        Distribution::new(&parse(json), Domain::FINITE, &Pointer::root()).unwrap()
    }

    /// `at_normal(z)` is `quantile(Phi(z))` where `Phi(z)` is exact enough (|z| <= 5) and never
    /// falls as `z` rises, for every kind, truncated or not; each value is finite out to 37
    /// standard deviations.
    #[test]
    fn a_standard_normal_maps_to_its_quantile_for_every_kind() {
        for json in [
            r#"{"kind": "fixed", "value": 3}"#,
            r#"{"kind": "normal", "mean": 0.224, "sd": 0.02}"#,
            r#"{"kind": "normal", "mean": 0.224, "sd": 0.02, "min": 0.01}"#,
            r#"{"kind": "normal", "mean": 0.224, "sd": 0.02, "min": 0.2, "max": 0.26}"#,
            r#"{"kind": "lognormal", "median": 2e8, "sigma": 0.15}"#,
            r#"{"kind": "lognormal", "median": 2e8, "sigma": 0.15, "min": 1.5e8, "max": 3e8}"#,
            r#"{"kind": "weibull", "scale": 100, "shape": 2}"#,
            r#"{"kind": "weibull", "scale": 100, "shape": 2, "min": 20, "max": 300}"#,
            r#"{"kind": "uniform", "min": 1, "max": 4}"#,
            r#"{"kind": "triangular", "min": 1, "mode": 1.5, "max": 4}"#,
        ] {
            let d = distribution(json);
            for i in -50..=50 {
                let z = f64::from(i) / 10.0;
                assert_relative_eq!(
                    d.at_normal(z),
                    d.quantile(standard_normal_cdf(z)),
                    max_relative = 1e-9
                );
            }
            let mut last = f64::NEG_INFINITY;
            for i in -400..=400 {
                let z = f64::from(i) / 10.0;
                let x = d.at_normal(z);
                assert!(
                    x.is_finite() && x >= last,
                    "{json}: {x} at {z} after {last}"
                );
                last = x;
            }
        }
    }

    /// Where `Phi(z)` rounds to 1 (beyond about 8.1), an unbounded upper tail still maps each `z`
    /// to its own value: the normal's `mean + sd z`, the lognormal's `median exp(sigma z)`, the
    /// Weibull's `scale (-ln Phi(-z))^(1 / shape)` (mpmath at 40 digits: 729.597732661721 at
    /// z = 10, 798.905088821092 at 11).
    #[test]
    fn an_upper_tail_keeps_its_precision_beyond_eight_standard_deviations() {
        let normal = distribution(r#"{"kind": "normal", "mean": 0.224, "sd": 0.02}"#);
        assert_eq!(normal.at_normal(10.0), 0.224 + 0.02 * 10.0);
        let bounded_below =
            distribution(r#"{"kind": "normal", "mean": 0.224, "sd": 0.02, "min": 0.01}"#);
        for z in [9.0, 10.0, 11.5] {
            assert_relative_eq!(
                bounded_below.at_normal(z),
                0.224 + 0.02 * z,
                max_relative = 1e-12
            );
        }
        let lognormal = distribution(r#"{"kind": "lognormal", "median": 2e8, "sigma": 0.15}"#);
        assert_relative_eq!(
            lognormal.at_normal(10.0),
            2e8 * 1.5_f64.exp(),
            max_relative = 1e-15
        );
        let weibull = distribution(r#"{"kind": "weibull", "scale": 100, "shape": 2}"#);
        assert_relative_eq!(
            weibull.at_normal(10.0),
            729.597_732_661_721_4,
            max_relative = 1e-12
        );
        assert_relative_eq!(
            weibull.at_normal(11.0),
            798.905_088_821_092_2,
            max_relative = 1e-12
        );
        for d in [normal, bounded_below, lognormal, weibull] {
            assert!(d.at_normal(8.5) < d.at_normal(9.0) && d.at_normal(11.0) < d.at_normal(11.5));
        }
    }

    #[test]
    fn normal_quantile_matches_known_values() {
        // Independent values (scipy.stats.norm.ppf, scipy 1.x).
        for (p, x) in [
            (0.975, 1.959_963_984_540_054),
            (0.5, 0.0),
            (0.1, -1.281_551_565_544_600_5),
            (1e-10, -6.361_340_902_404_056),
            (1e-300, -37.047_096_299_361_2),
        ] {
            let got = standard_normal_quantile(p);
            assert!(
                (got - x).abs() <= 1e-12 * x.abs().max(1.0),
                "p = {p}: {got} vs {x}"
            );
        }
        assert_relative_eq!(
            standard_normal_cdf(1.959_963_984_540_054),
            0.975,
            max_relative = 1e-15
        );
    }

    #[test]
    fn a_distribution_that_can_leave_the_domain_is_rejected_naming_the_field() {
        let (positive, non_negative) = (Domain::POSITIVE, Domain::NON_NEGATIVE);
        let above = Domain {
            lower: 1e-3,
            inclusive: true,
        };
        let cases = [
            (r#"{"kind":"normal","mean":1,"sd":0.1}"#, positive, "/d/min"),
            (
                r#"{"kind":"normal","mean":1,"sd":0.1,"min":0}"#,
                positive,
                "/d/min",
            ),
            (
                r#"{"kind":"normal","mean":1,"sd":0.1,"min":2}"#,
                positive,
                "/d/min",
            ),
            (
                r#"{"kind":"normal","mean":1,"sd":0,"min":0.5}"#,
                positive,
                "/d/sd",
            ),
            // Refused for its sd alone: no `min` to suggest for values it cannot have.
            (r#"{"kind":"normal","mean":0.3,"sd":0}"#, positive, "/d/sd"),
            (r#"{"kind":"normal","mean":0.3,"sd":-1}"#, positive, "/d/sd"),
            (
                r#"{"kind":"normal","mean":1,"sd":1,"min":0.5,"max":0.4}"#,
                positive,
                "/d/max",
            ),
            (r#"{"kind":"uniform","min":-1,"max":1}"#, positive, "/d/min"),
            (r#"{"kind":"uniform","min":1,"max":1}"#, positive, "/d/max"),
            (
                r#"{"kind":"triangular","min":1,"mode":3,"max":2}"#,
                positive,
                "/d/mode",
            ),
            (
                r#"{"kind":"lognormal","median":-1,"sigma":0.1}"#,
                positive,
                "/d/median",
            ),
            (
                r#"{"kind":"lognormal","median":1,"sigma":0}"#,
                positive,
                "/d/sigma",
            ),
            (
                r#"{"kind":"weibull","scale":1,"shape":-2}"#,
                positive,
                "/d/shape",
            ),
            (r#"{"kind":"fixed","value":0}"#, positive, "/d/value"),
            (
                r#"{"kind":"lognormal","median":1,"sigma":0.1}"#,
                above,
                "/d/kind",
            ),
            (
                r#"{"kind":"weibull","scale":1,"shape":2}"#,
                above,
                "/d/kind",
            ),
        ];
        for (json, domain, pointer) in cases {
            assert_eq!(pointers(json, domain), [pointer], "{json}");
        }
        assert!(
            pointers(
                r#"{"kind":"normal","mean":1,"sd":0.1,"min":0}"#,
                non_negative
            )
            .is_empty()
        );
    }

    /// No draw may leave the magnitudes a scenario admits (1e30), however far out it lies: a range
    /// up to 1e308 was accepted, and its draws made every metric NaN. The farthest score of any
    /// draw decides; an untruncated distribution that reaches past is told to add a `max`.
    #[test]
    fn a_distribution_that_reaches_past_the_largest_magnitude_is_rejected() {
        let (positive, finite) = (Domain::POSITIVE, Domain::FINITE);
        let cases = [
            (
                r#"{"kind":"uniform","min":0.007,"max":1e308}"#,
                positive,
                "/d/max",
            ),
            (
                r#"{"kind":"uniform","min":1,"max":2e30}"#,
                positive,
                "/d/max",
            ),
            (
                r#"{"kind":"triangular","min":0.3,"mode":0.344,"max":1e308}"#,
                positive,
                "/d/max",
            ),
            (r#"{"kind":"fixed","value":1.5e30}"#, positive, "/d/value"),
            (
                r#"{"kind":"lognormal","median":1e308,"sigma":1}"#,
                positive,
                "/d/max",
            ),
            (
                r#"{"kind":"lognormal","median":1e-3,"sigma":1e308,"min":1e-5}"#,
                positive,
                "/d/max",
            ),
            // 1e14 exp(37): within reach of the rare events' farthest inputs.
            (
                r#"{"kind":"lognormal","median":1e14,"sigma":1}"#,
                positive,
                "/d/max",
            ),
            (
                r#"{"kind":"lognormal","median":1e9,"sigma":2,"max":1e31}"#,
                positive,
                "/d/max",
            ),
            (
                r#"{"kind":"weibull","scale":1e308,"shape":2}"#,
                positive,
                "/d/max",
            ),
            (
                r#"{"kind":"weibull","scale":1,"shape":0.01}"#,
                positive,
                "/d/max",
            ),
            (
                r#"{"kind":"normal","mean":1e30,"sd":1e28,"min":1}"#,
                positive,
                "/d/max",
            ),
            (
                r#"{"kind":"normal","mean":1,"sd":1e29,"min":0.5}"#,
                positive,
                "/d/max",
            ),
            (
                r#"{"kind":"normal","mean":9e29,"sd":1e28}"#,
                finite,
                "/d/max",
            ),
            (
                r#"{"kind":"normal","mean":-1e30,"sd":1e20,"max":0}"#,
                finite,
                "/d/min",
            ),
            (
                r#"{"kind":"uniform","min":-1e308,"max":0}"#,
                finite,
                "/d/min",
            ),
            (r#"{"kind":"fixed","value":-2e30}"#, finite, "/d/value"),
        ];
        for (json, domain, pointer) in cases {
            assert_eq!(pointers(json, domain), [pointer], "{json}");
        }
        let told = Distribution::new(
            &parse(r#"{"kind":"lognormal","median":1e14,"sigma":1}"#),
            positive,
            &Pointer::root(),
        )
        .unwrap_err();
        assert!(
            told[0].detail.contains(r#"add a "max" of at most 1e30"#),
            "{told:?}"
        );
    }

    /// No positive draw may fall below the least magnitude a scenario admits (1e-30) either: a
    /// fixed breakdown field of 1e-300 ran, to an arc energy of 2.9e304 J and plastic work beyond
    /// f64. A fixed value or a `min` there is refused, as is a lognormal that reaches there
    /// untruncated and a Weibull of that scale; zero, where the parameter takes it, stays.
    #[test]
    fn a_distribution_that_reaches_below_the_least_magnitude_is_rejected() {
        let (positive, non_negative) = (Domain::POSITIVE, Domain::NON_NEGATIVE);
        let cases = [
            (r#"{"kind":"fixed","value":1e-300}"#, positive, "/d/value"),
            (
                r#"{"kind":"fixed","value":1e-40}"#,
                non_negative,
                "/d/value",
            ),
            (
                r#"{"kind":"uniform","min":1e-300,"max":2e-300}"#,
                positive,
                "/d/min",
            ),
            (
                r#"{"kind":"triangular","min":1e-31,"mode":0.3,"max":1}"#,
                non_negative,
                "/d/min",
            ),
            (
                r#"{"kind":"normal","mean":1e-29,"sd":1e-31,"min":1e-35}"#,
                positive,
                "/d/min",
            ),
            (
                r#"{"kind":"lognormal","median":1e-300,"sigma":1}"#,
                positive,
                "/d/min",
            ),
            // 1e-5 exp(-74): within reach of the rare events' farthest inputs.
            (
                r#"{"kind":"lognormal","median":1e-5,"sigma":2}"#,
                positive,
                "/d/min",
            ),
            (
                r#"{"kind":"weibull","scale":1e-300,"shape":2}"#,
                positive,
                "/d/scale",
            ),
            // From 0, every positive draw below 1e-30: a velocity of 1e-35 m/s ran to an arc
            // energy of 4.6e28 J; and a draw of 5e-324 past f64.
            (
                r#"{"kind":"uniform","min":0,"max":5e-324}"#,
                non_negative,
                "/d/max",
            ),
            (
                r#"{"kind":"triangular","min":0,"mode":0,"max":1e-31}"#,
                non_negative,
                "/d/max",
            ),
            (
                r#"{"kind":"normal","mean":0,"sd":1e-300,"min":0}"#,
                non_negative,
                "/d/mean",
            ),
            (
                r#"{"kind":"normal","mean":1e-35,"sd":1e-36,"min":0}"#,
                non_negative,
                "/d/mean",
            ),
        ];
        for (json, domain, pointer) in cases {
            assert_eq!(pointers(json, domain), [pointer], "{json}");
        }
    }

    /// What [`a_distribution_that_reaches_below_the_least_magnitude_is_rejected`] tells: a tiny
    /// number written as one, the parameter's own rule; and what it lets through.
    #[test]
    fn the_least_magnitude_is_told_as_the_parameters_rule_and_zero_stays_where_it_may() {
        let (positive, non_negative) = (Domain::POSITIVE, Domain::NON_NEGATIVE);
        // A tiny number is written as one, not in 300 decimals.
        let told = Distribution::new(
            &parse(r#"{"kind":"normal","mean":1e-300,"sd":1e-301}"#),
            positive,
            &Pointer::root(),
        )
        .unwrap_err();
        assert!(
            told[0]
                .detail
                .starts_with("a normal(mean 1e-300, sd 1e-301) reaches below 0"),
            "{told:?}"
        );
        // The rule told is the parameter's own: 0 only where it takes 0 (an HTTP probe found a
        // positive parameter's 1e-31 told "must be 0 or at least 1e-30", and its 0 refused).
        for (domain, rule) in [
            (
                positive,
                "must be at least 1e-30 (the supported range), got 1e-31",
            ),
            (
                non_negative,
                "must be 0 or at least 1e-30 (the supported range), got 1e-31",
            ),
        ] {
            let fixed = parse(r#"{"kind":"fixed","value":1e-31}"#);
            let told = Distribution::new(&fixed, domain, &Pointer::root()).unwrap_err();
            assert_eq!(told[0].detail, rule);
        }
        for (json, domain) in [
            (r#"{"kind":"fixed","value":0}"#, non_negative),
            (r#"{"kind":"fixed","value":1e-30}"#, positive),
            (r#"{"kind":"uniform","min":0,"max":1e-29}"#, non_negative),
            (
                r#"{"kind":"lognormal","median":1e-5,"sigma":2,"min":1e-30}"#,
                positive,
            ),
            (
                r#"{"kind":"lognormal","median":1e-3,"sigma":0.5}"#,
                positive,
            ),
        ] {
            assert!(pointers(json, domain).is_empty(), "{json}");
        }
    }

    /// A positive parameter draws no 0, even where a Weibull's draws round to it: they are drawn
    /// again, and its quantiles keep above 0 too; a parameter that takes
    /// 0 keeps its window from 0. A window the least positive value leaves too little of is
    /// refused, saying so (a shape of 1e-30 draws 0 or infinity alone; kappa of 0 ran to e1 = 0).
    #[test]
    fn a_positive_parameter_never_draws_zero() {
        let spec = parse(r#"{"kind":"weibull","scale":1.593e-5,"shape":0.01,"max":1e30}"#);
        let positive = Distribution::new(&spec, Domain::POSITIVE, &Pointer::root()).unwrap();
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        let draws = 200_000;
        for _ in 0..draws {
            let x = positive.sample(&mut rng);
            assert!(x > 0.0, "{x}");
        }
        assert!(positive.quantile(1e-6) > 0.0);
        let non_negative =
            Distribution::new(&spec, Domain::NON_NEGATIVE, &Pointer::root()).unwrap();
        assert_eq!(non_negative.quantile(1e-6), 0.0);
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        let zeros = (0..draws)
            .filter(|_| non_negative.sample(&mut rng) == 0.0)
            .count();
        // P(a draw rounds to 0) = 1 - exp(-(5e-324 / 1.593e-5)^0.01) = 6.5e-4, of the 0.89
        // within the max: 146 expected.
        assert!((80..=220).contains(&zeros), "{zeros}");
        let told = Distribution::new(
            &parse(r#"{"kind":"weibull","scale":1.593e-5,"shape":1e-30,"max":1e30}"#),
            Domain::POSITIVE,
            &Pointer::root(),
        )
        .unwrap_err();
        assert_eq!(told[0].pointer, "/min", "{told:?}");
        assert!(
            told[0].detail.starts_with(
                "the window [the least positive f64 (this parameter takes no 0), max] keeps only 0"
            ),
            "{told:?}"
        );
    }

    /// Wide but sane distributions, and the same ones truncated at the largest magnitude, stay
    /// within what a scenario admits.
    #[test]
    fn a_wide_distribution_within_the_largest_magnitude_is_accepted() {
        let (positive, finite) = (Domain::POSITIVE, Domain::FINITE);
        for (json, domain) in [
            (
                r#"{"kind":"lognormal","median":1e9,"sigma":2,"max":1e30}"#,
                positive,
            ),
            (r#"{"kind":"lognormal","median":1e9,"sigma":0.5}"#, positive),
            (
                r#"{"kind":"normal","mean":0.224,"sd":0.02,"min":0.05}"#,
                positive,
            ),
            (r#"{"kind":"weibull","scale":2e5,"shape":1.5}"#, positive),
            (r#"{"kind":"uniform","min":1,"max":1e30}"#, positive),
            (r#"{"kind":"fixed","value":1e30}"#, positive),
            (r#"{"kind":"normal","mean":-5,"sd":100}"#, finite),
            (r#"{"kind":"uniform","min":-1e30,"max":1e30}"#, finite),
        ] {
            assert!(pointers(json, domain).is_empty(), "{json}");
        }
    }

    #[test]
    fn unknown_kinds_and_fields_do_not_parse() {
        assert!(serde_json::from_str::<DistributionSpec>(r#"{"kind":"cauchy","x0":1}"#).is_err());
        assert!(
            serde_json::from_str::<DistributionSpec>(r#"{"kind":"fixed","value":1,"sd":2}"#)
                .is_err()
        );
    }

    /// Each of [`POSITIVE_MEMBERS`] refuses 0 in every kind that has it, whatever the parameter;
    /// the other members take 0 where the parameter may be 0 or below.
    #[test]
    fn the_positive_members_are_those_listed() {
        let kinds = [
            r#"{"kind":"fixed","value":1}"#,
            r#"{"kind":"normal","mean":1,"sd":1}"#,
            r#"{"kind":"lognormal","median":1,"sigma":1}"#,
            r#"{"kind":"uniform","min":-1,"max":1}"#,
            r#"{"kind":"triangular","min":-1,"mode":0,"max":1}"#,
            r#"{"kind":"weibull","scale":1,"shape":1}"#,
        ];
        let mut listed = 0;
        for kind in kinds {
            let spec: serde_json::Value = serde_json::from_str(kind).unwrap();
            for member in spec.as_object().unwrap().keys().filter(|m| *m != "kind") {
                let mut zero = spec.clone();
                zero[member] = serde_json::json!(0);
                let refused =
                    pointers(&zero.to_string(), Domain::FINITE) == [format!("/d/{member}")];
                let positive = POSITIVE_MEMBERS.contains(&member.as_str());
                assert_eq!(refused, positive, "{zero}");
                listed += usize::from(positive);
            }
        }
        assert_eq!(listed, POSITIVE_MEMBERS.len());
    }

    /// A truncation bound given as `null` is left out, as the OpenAPI document's
    /// `["number", "null"]` says (a client that writes absent members as `null` was refused); a
    /// member a kind needs is still a number.
    #[test]
    fn a_null_truncation_bound_is_no_bound_and_a_needed_member_is_a_number() {
        for (written, meant) in [
            (
                r#"{"kind":"normal","mean":1,"sd":0.1,"min":0.5,"max":null}"#,
                r#"{"kind":"normal","mean":1,"sd":0.1,"min":0.5}"#,
            ),
            (
                r#"{"kind":"lognormal","median":1,"sigma":0.1,"min":null,"max":null}"#,
                r#"{"kind":"lognormal","median":1,"sigma":0.1}"#,
            ),
            (
                r#"{"max":null,"kind":"weibull","scale":1,"shape":2}"#,
                r#"{"kind":"weibull","scale":1,"shape":2}"#,
            ),
        ] {
            assert_eq!(parse(written), parse(meant), "{written}");
        }
        for needed in [
            r#"{"kind":"uniform","min":null,"max":1}"#,
            r#"{"kind":"normal","mean":1,"sd":null}"#,
            r#"{"sd":null,"kind":"normal","mean":1}"#,
            r#"{"kind":"fixed","value":null}"#,
        ] {
            let error = serde_json::from_str::<DistributionSpec>(needed).unwrap_err();
            assert!(error.to_string().contains("null"), "{needed}: {error}");
        }
    }

    #[test]
    fn draws_stay_in_the_truncation_window_and_have_the_right_mean() {
        let spec = parse(r#"{"kind":"normal","mean":1,"sd":1,"min":0.5,"max":3}"#);
        let d = Distribution::new(&spec, Domain::POSITIVE, &Pointer::root()).unwrap();
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let n = 200_000;
        let draws: Vec<f64> = (0..n).map(|_| d.sample(&mut rng)).collect();
        assert!(draws.iter().all(|x| (0.5..=3.0).contains(x)));
        // E[X | a < X < b] = mu + sd (phi(a') - phi(b')) / (Phi(b') - Phi(a'))
        let phi = |x: f64| (-0.5 * x * x).exp() / (2.0 * std::f64::consts::PI).sqrt();
        let (a, b) = (-0.5, 2.0);
        let expected = 1.0 + (phi(a) - phi(b)) / (standard_normal_cdf(b) - standard_normal_cdf(a));
        let mean = draws.iter().sum::<f64>() / f64::from(n);
        assert!((mean - expected).abs() < 0.005, "{mean} vs {expected}");
    }

    #[test]
    fn quantile_inverts_each_cdf() {
        let cases = [
            (r#"{"kind":"uniform","min":2,"max":4}"#, 0.25, 2.5),
            (
                r#"{"kind":"triangular","min":0,"mode":1,"max":2}"#,
                0.125,
                0.5,
            ),
            (
                r#"{"kind":"triangular","min":0,"mode":1,"max":2}"#,
                0.875,
                1.5,
            ),
            (r#"{"kind":"lognormal","median":2,"sigma":0.5}"#, 0.5, 2.0),
            (
                r#"{"kind":"weibull","scale":3,"shape":2}"#,
                1.0 - (-1.0f64).exp(),
                3.0,
            ),
            (
                r#"{"kind":"normal","mean":5,"sd":2,"min":0}"#,
                0.5,
                5.0 + 2.0 * 0.007_782_739_908_188_287,
            ),
        ];
        for (json, u, x) in cases {
            let d =
                Distribution::new(&parse(json), Domain::NON_NEGATIVE, &Pointer::root()).unwrap();
            assert_relative_eq!(d.quantile(u), x, max_relative = 1e-9);
        }
    }

    /// An untruncated CDF.
    type Cdf = fn(f64) -> f64;

    /// Truncated lognormal and Weibull specs with the untruncated CDF of each.
    fn truncated_cases() -> [(DistributionSpec, Cdf); 2] {
        [
            (
                parse(r#"{"kind":"lognormal","median":1,"sigma":0.5,"min":0.8,"max":3}"#),
                |x: f64| standard_normal_cdf(x.ln() / 0.5),
            ),
            (
                parse(r#"{"kind":"weibull","scale":2,"shape":3,"min":1,"max":2.5}"#),
                |x: f64| 1.0 - (-(x / 2.0).powi(3)).exp(),
            ),
        ]
    }

    fn truncated(spec: &DistributionSpec) -> (Distribution, Window) {
        match Distribution::new(spec, Domain::POSITIVE, &Pointer::root()).unwrap() {
            d @ (Distribution::Lognormal { window, .. } | Distribution::Weibull { window, .. }) => {
                (d, window)
            }
            other => unreachable!("not a truncated case: {other:?}"),
        }
    }

    #[test]
    fn truncated_lognormal_and_weibull_draws_stay_in_the_window_and_count_rejections() {
        for (spec, cdf) in truncated_cases() {
            let (d, window) = truncated(&spec);
            let mut rng = ChaCha8Rng::seed_from_u64(3);
            let (n, mut rejections) = (100_000, 0);
            let inside = (0..n)
                .map(|_| d.sample_counting(&mut rng, &mut rejections))
                .all(|x| (window.min..=window.max).contains(&x));
            assert!(inside, "{spec:?}");
            let kept = cdf(window.max) - cdf(window.min);
            // Each kept draw costs 1 / kept draws on average: (1 - kept) / kept rejections.
            let expected = f64::from(n) * (1.0 - kept) / kept;
            assert!(
                (rejections as f64 - expected).abs() < 0.03 * expected,
                "{spec:?}: {rejections} vs {expected}"
            );
        }
    }

    proptest::proptest! {
        #[test]
        fn a_truncated_quantile_inverts_the_truncated_cdf(u in 0.001f64..0.999) {
            for (spec, cdf) in truncated_cases() {
                let (d, window) = truncated(&spec);
                let x = d.quantile(u);
                proptest::prop_assert!((window.min..=window.max).contains(&x));
                let truncated_cdf =
                    (cdf(x) - cdf(window.min)) / (cdf(window.max) - cdf(window.min));
                proptest::prop_assert!((truncated_cdf - u).abs() < 1e-9, "{spec:?}: {truncated_cdf} vs {u}");
            }
        }
    }
}
