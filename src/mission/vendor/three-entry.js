// The parts of three.js that scarp's report.html uses, bundled as one classic script exposing
// the global `THREE` (see README.md beside the bundle).
export {
  AmbientLight, Box3, BufferAttribute, BufferGeometry, Color, DirectionalLight, DoubleSide,
  Group, HemisphereLight, Line, LineBasicMaterial, LineLoop, Mesh, MeshBasicMaterial,
  MeshStandardMaterial, PerspectiveCamera, Points, PointsMaterial, Scene, Sphere,
  SphereGeometry, Spherical, Vector3, WebGLRenderer, GridHelper,
} from 'three';
