//! The mesh-convolutional autoencoder as a Burn [`Module`]: parameters, initialisation, and a
//! pure-Burn forward pass (the autodiff reference; training uses the hand-written pass of
//! [`super::engine`], which computes the same function).
//!
//! Conventions (docs/design.md § Mesh autoencoder):
//! - features of one shape `X ∈ R^{N×9}`; a batch is `[B, N, 9]`;
//! - convolution `y_i = W_point·x_i + W_nb·mean_{j∈N(i)} x_j + b` with `W ∈ R^{9×9}` stored
//!   `[out, in]`;
//! - encoder: L layers, tanh (the last one linear when L > 1); flatten vertex-major
//!   (`f[i·9 + c] = x_i,c`); `z = C·f`, `C ∈ R^{K×9N}` (stored as row blocks of
//!   [`COMPONENT_BLOCK`] components: the layout of saved models; training keeps `C` as one plain
//!   buffer, see [`super::training`]);
//! - decoder: `f̂ = Cᵀz`, then the layers in reverse order with the transposed weights
//!   (`y_i = W_pointᵀ·x_i + W_nbᵀ·mean x_j + b_dec`), tanh on every layer.

use burn::module::{Module, Param};
use burn::tensor::{Device, Int, Tensor, TensorData};

use super::config::AutoencoderConfig;
use super::neighbors::NeighborIndex;
use super::rng::Rng;

/// One 9 → 9 mesh-convolution layer of the encoder, with the bias of its mirrored decoder layer.
#[derive(Module, Debug)]
pub struct MeshConv {
    /// `W_point`, shape `[9 (out), 9 (in)]`.
    pub weight_point: Param<Tensor<2>>,
    /// `W_nb`, shape `[9 (out), 9 (in)]`.
    pub weight_neighbor: Param<Tensor<2>>,
    /// Encoder bias, shape `[9]`.
    pub bias: Param<Tensor<1>>,
    /// Bias of the decoder layer that uses this layer's transposed weights, shape `[9]`.
    pub decoder_bias: Param<Tensor<1>>,
}

/// Rows (components) per parameter block of `C`.
pub const COMPONENT_BLOCK: usize = 8;

/// All trainable parameters of the autoencoder.
#[derive(Module, Debug)]
pub struct AutoencoderModule {
    /// Encoder layers in forward order (the decoder runs them in reverse).
    pub layers: Vec<MeshConv>,
    /// Latent map `C` `[K, 9N]` (columns in vertex-major order `i·9 + c`) as consecutive row
    /// blocks: block `j` holds components `j·COMPONENT_BLOCK ..`, shape `[≤ COMPONENT_BLOCK, 9N]`.
    pub components: Vec<Param<Tensor<2>>>,
}

/// Initial weights of one layer as plain arrays (`[out][in]` row-major): `W_point`, `W_nb`.
pub type LayerInit = [Vec<f32>; 2];

impl AutoencoderConfig {
    /// The initial parameters as plain arrays for a mesh of `n_vertices` vertices: weights and
    /// `C` from N(0, init_std²) drawn from the seeded generator (layer by layer `W_point`,
    /// `W_nb`, then `C` `[K, 9N]`); the biases start at 0.
    pub fn init_arrays(&self, n_vertices: usize) -> (Vec<LayerInit>, Vec<f32>) {
        let mut rng = Rng::new(self.seed);
        let std = self.init_std;
        let layers = (0..self.layers).map(|_| [rng.normal_vec(81, std), rng.normal_vec(81, std)]).collect();
        let c = rng.normal_vec(self.components * 9 * n_vertices, std);
        (layers, c)
    }

    /// Initialises the parameters for a mesh of `n_vertices` vertices (the values of
    /// [`Self::init_arrays`]).
    pub fn init(&self, n_vertices: usize, device: &Device) -> AutoencoderModule {
        let (layers, c) = self.init_arrays(n_vertices);
        AutoencoderModule {
            layers: layers.iter().map(|[wp, wn]| MeshConv::from_arrays(wp, wn, &[0.0; 9], &[0.0; 9], device)).collect(),
            components: AutoencoderModule::component_blocks(&c, n_vertices, device),
        }
    }
}

impl MeshConv {
    /// A layer from plain arrays (`[out][in]` row-major weights).
    pub fn from_arrays(wp: &[f32], wn: &[f32], bias: &[f32; 9], decoder_bias: &[f32; 9], device: &Device) -> Self {
        MeshConv {
            weight_point: Param::from_data(TensorData::new(wp.to_vec(), [9, 9]), device),
            weight_neighbor: Param::from_data(TensorData::new(wn.to_vec(), [9, 9]), device),
            bias: Param::from_data(TensorData::new(bias.to_vec(), [9]), device),
            decoder_bias: Param::from_data(TensorData::new(decoder_bias.to_vec(), [9]), device),
        }
    }
}

/// The neighbour index as tensors for the Burn graph: a padded gather index and `1/|N(i)|`.
#[derive(Debug, Clone)]
pub struct NeighborTensors {
    index: Tensor<1, Int>,
    inv_degree: Tensor<3>,
    n: usize,
    d: usize,
}

impl NeighborTensors {
    /// Builds the tensors on `device`.
    pub fn new(nb: &NeighborIndex, device: &Device) -> Self {
        let n = nb.n_vertices();
        let (idx, d) = nb.padded();
        let inv: Vec<f32> = (0..n).map(|i| nb.inv_degree(i)).collect();
        NeighborTensors {
            index: Tensor::from_data(TensorData::new(idx, [n * d]), device),
            inv_degree: Tensor::from_data(TensorData::new(inv, [1, n, 1]), device),
            n,
            d,
        }
    }

    /// Neighbour mean of every vertex (zero for a vertex without neighbours).
    ///
    /// # Shapes
    /// - `x`: `[B, N, C]`
    /// - output: `[B, N, C]`
    pub fn mean(&self, x: Tensor<3>) -> Tensor<3> {
        let [b, n, c] = x.dims();
        debug_assert_eq!(n, self.n);
        let zero = Tensor::<3>::zeros([b, 1, c], &x.device());
        let padded = Tensor::cat(vec![x, zero], 1);
        let gathered = padded.select(1, self.index.clone()).reshape([b, n, self.d, c]);
        gathered.sum_dim(2).reshape([b, n, c]) * self.inv_degree.clone()
    }
}

impl MeshConv {
    /// Encoder convolution `y_i = W_point·x_i + W_nb·mean x_j + b`, then tanh if `tanh`.
    ///
    /// # Shapes
    /// - `x`: `[B, N, 9]`
    /// - output: `[B, N, 9]`
    pub fn forward_encoder(&self, x: Tensor<3>, nb: &NeighborTensors, tanh: bool) -> Tensor<3> {
        let [b, n, c] = x.dims();
        let m = nb.mean(x.clone());
        let y = x.reshape([b * n, c]).matmul(self.weight_point.val().transpose())
            + m.reshape([b * n, c]).matmul(self.weight_neighbor.val().transpose())
            + self.bias.val().unsqueeze::<2>();
        let y = y.reshape([b, n, c]);
        if tanh { y.tanh() } else { y }
    }

    /// Decoder convolution with the tied, transposed weights:
    /// `y_i = tanh(W_pointᵀ·x_i + W_nbᵀ·mean x_j + b_dec)`.
    ///
    /// # Shapes
    /// - `x`: `[B, N, 9]`
    /// - output: `[B, N, 9]`
    pub fn forward_decoder(&self, x: Tensor<3>, nb: &NeighborTensors) -> Tensor<3> {
        let [b, n, c] = x.dims();
        let m = nb.mean(x.clone());
        let y = x.reshape([b * n, c]).matmul(self.weight_point.val())
            + m.reshape([b * n, c]).matmul(self.weight_neighbor.val())
            + self.decoder_bias.val().unsqueeze::<2>();
        y.reshape([b, n, c]).tanh()
    }
}

impl AutoencoderModule {
    /// Number of layers L.
    pub fn n_layers(&self) -> usize {
        self.layers.len()
    }

    /// `[K, 9N]`, the shape of `C`.
    pub fn components_shape(&self) -> [usize; 2] {
        let mut k = 0;
        let mut nc = 0;
        for p in &self.components {
            let [r, c] = p.lazy_shape().dims::<2>();
            k += r;
            nc = c;
        }
        [k, nc]
    }

    /// `C` (`[K, 9N]` row-major) as fresh parameter blocks of [`COMPONENT_BLOCK`] rows (copies).
    pub fn component_blocks(c: &[f32], n_vertices: usize, device: &Device) -> Vec<Param<Tensor<2>>> {
        let nc = 9 * n_vertices;
        c.chunks(COMPONENT_BLOCK * nc.max(1))
            .map(|rows| Param::from_data(TensorData::new(rows.to_vec(), [rows.len() / nc.max(1), nc]), device))
            .collect()
    }

    /// `C` as one tensor (the blocks concatenated).
    ///
    /// # Shapes
    /// output: `[K, 9N]`
    pub fn components_tensor(&self) -> Tensor<2> {
        Tensor::cat(self.components.iter().map(|p| p.val()).collect(), 0)
    }

    /// Encoder: convolutions, flatten, `z = C·f`.
    ///
    /// # Shapes
    /// - `x`: `[B, N, 9]`
    /// - output `Z`: `[B, K]`
    pub fn encode(&self, x: Tensor<3>, nb: &NeighborTensors) -> Tensor<2> {
        let l = self.layers.len();
        let mut h = x;
        for (i, layer) in self.layers.iter().enumerate() {
            let tanh = !(l > 1 && i == l - 1);
            h = layer.forward_encoder(h, nb, tanh);
        }
        let [b, n, c] = h.dims();
        h.reshape([b, n * c]).matmul(self.components_tensor().transpose())
    }

    /// Decoder: `f̂ = Cᵀz`, then the tied convolutions in reverse order.
    ///
    /// # Shapes
    /// - `z`: `[B, K]`
    /// - output: `[B, N, 9]`
    pub fn decode(&self, z: Tensor<2>, nb: &NeighborTensors) -> Tensor<3> {
        let [b, _] = z.dims();
        let f = z.matmul(self.components_tensor());
        let [_, nc] = f.dims();
        let mut h = f.reshape([b, nc / 9, 9]);
        for layer in self.layers.iter().rev() {
            h = layer.forward_decoder(h, nb);
        }
        h
    }

    /// Encode then decode.
    ///
    /// # Shapes
    /// - `x`: `[B, N, 9]`
    /// - output: (`X̂` `[B, N, 9]`, `Z` `[B, K]`)
    pub fn forward(&self, x: Tensor<3>, nb: &NeighborTensors) -> (Tensor<3>, Tensor<2>) {
        let z = self.encode(x, nb);
        (self.decode(z.clone(), nb), z)
    }
}
