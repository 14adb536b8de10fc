//! Settings in a report's prose as a person writes them (`SGD, lr 0.01`, `ReLU`, `[256, 256]`),
//! never as Rust's `Debug` prints the configuration types.

use serde::Serialize;
use tandem_models::{GainStructure, OptimizerConfig};
use tandem_nn::{AdaGradConfig, AdamConfig, SgdConfig};

/// A list as TOML writes it: `[256, 256]` (an empty list is `[]`).
pub fn list<T: std::fmt::Display>(items: &[T]) -> String {
    let items: Vec<String> = items.iter().map(T::to_string).collect();
    format!("[{}]", items.join(", "))
}

/// A list of reals as TOML writes it, a whole number with its `.0`: `[0.75, 0.0]`.
pub fn reals(items: &[f64]) -> String {
    // `{:?}` of an `f64` is its shortest round-trip form with `.0` kept, TOML's float syntax.
    let items: Vec<String> = items.iter().map(|x| format!("{x:?}")).collect();
    format!("[{}]", items.join(", "))
}

/// An optimizer and the settings that differ from its defaults: `SGD, lr 0.01`,
/// `Adam, lr 0.001, weight decay 0.0001`.
pub fn optimizer(o: &OptimizerConfig) -> String {
    let mut parts = Vec::new();
    match o {
        OptimizerConfig::Adam(c) => {
            let d = AdamConfig::default();
            parts.push(format!("Adam, lr {}", c.lr));
            if (c.beta1, c.beta2) != (d.beta1, d.beta2) {
                parts.push(format!("β {} and {}", c.beta1, c.beta2));
            }
            if c.eps != d.eps {
                parts.push(format!("ε {:e}", c.eps));
            }
            if c.weight_decay != 0.0 {
                let kind = if c.decoupled { "decoupled " } else { "" };
                parts.push(format!("{kind}weight decay {}", c.weight_decay));
            }
        }
        OptimizerConfig::AdaGrad(c) => {
            let d = AdaGradConfig::default();
            parts.push(format!("AdaGrad, lr {}", c.lr));
            if c.lr_decay != 0.0 {
                parts.push(format!("lr decay {}", c.lr_decay));
            }
            if c.initial_accumulator != d.initial_accumulator {
                parts.push(format!("initial accumulator {}", c.initial_accumulator));
            }
            if c.eps != d.eps {
                parts.push(format!("ε {:e}", c.eps));
            }
            if c.weight_decay != 0.0 {
                parts.push(format!("weight decay {}", c.weight_decay));
            }
        }
        OptimizerConfig::Sgd(c) => {
            let d = SgdConfig::default();
            parts.push(format!("SGD, lr {}", c.lr));
            if c.momentum != d.momentum {
                let nesterov = if c.nesterov { "Nesterov " } else { "" };
                parts.push(format!("{nesterov}momentum {}", c.momentum));
            }
            if c.weight_decay != 0.0 {
                parts.push(format!("weight decay {}", c.weight_decay));
            }
        }
    }
    parts.join(", ")
}

/// An activation's usual name: `ReLU`, `tanh`, `SiLU`.
pub fn activation(a: tandem_nn::Activation) -> &'static str {
    use tandem_nn::Activation::*;
    match a {
        Identity => "linear",
        Relu => "ReLU",
        Tanh => "tanh",
        Sigmoid => "sigmoid",
        Elu => "ELU",
        Silu => "SiLU",
    }
}

/// The shape of p1's gain matrix `L`: `full` or `diagonal`.
pub fn gain_structure(s: GainStructure) -> &'static str {
    match s {
        GainStructure::Full => "full",
        GainStructure::Diagonal => "diagonal",
    }
}

/// A unit enum as its configuration file names it (`"normalize"` → `normalize`), for the types
/// this crate does not depend on.
pub fn config_name<T: Serialize>(v: &T) -> String {
    match serde_json::to_value(v) {
        Ok(serde_json::Value::String(s)) => s,
        Ok(other) => other.to_string(),
        Err(e) => format!("({e})"),
    }
}

/// REINFORCE's baseline in words, from its configuration name.
pub fn baseline<T: Serialize>(b: &T) -> String {
    match config_name(b).as_str() {
        "none" => "no baseline".into(),
        "normalize" => "returns standardized per update".into(),
        "value" => "a learned V(s) baseline".into(),
        other => format!("baseline {other}"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn settings_read_as_written() {
        assert_eq!(list(&[256, 256]), "[256, 256]");
        assert_eq!(list::<usize>(&[]), "[]");
        assert_eq!(reals(&[0.75, 0.0, -0.3]), "[0.75, 0.0, -0.3]");
        assert_eq!(optimizer(&OptimizerConfig::sgd(0.01)), "SGD, lr 0.01");
        assert_eq!(optimizer(&OptimizerConfig::adam(1e-2)), "Adam, lr 0.01");
        let mut adam = AdamConfig {
            lr: 1e-3,
            weight_decay: 1e-4,
            decoupled: true,
            ..AdamConfig::default()
        };
        assert_eq!(
            optimizer(&OptimizerConfig::Adam(adam)),
            "Adam, lr 0.001, decoupled weight decay 0.0001"
        );
        adam.eps = 1e-6;
        assert!(optimizer(&OptimizerConfig::Adam(adam)).contains("ε 1e-6"));
        let sgd = SgdConfig {
            momentum: 0.9,
            nesterov: true,
            ..SgdConfig::default()
        };
        assert_eq!(
            optimizer(&OptimizerConfig::Sgd(sgd)),
            "SGD, lr 0.01, Nesterov momentum 0.9"
        );
        assert_eq!(optimizer(&OptimizerConfig::adagrad(0.1)), "AdaGrad, lr 0.1");
        assert_eq!(activation(tandem_nn::Activation::Relu), "ReLU");
        assert_eq!(gain_structure(GainStructure::Full), "full");
        assert_eq!(config_name(&GainStructure::Diagonal), "diagonal");
    }
}
