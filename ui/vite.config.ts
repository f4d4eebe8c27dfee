import { defineConfig } from "vite";

// Reproducible output with fixed names (embedded by hal-sim/src/cli/ui.rs): no hashes, no
// source maps, one script, one style sheet and the live plot's worker.
export default defineConfig({
  base: "./",
  worker: {
    format: "es",
    rollupOptions: { output: { entryFileNames: "assets/[name].js" } },
  },
  build: {
    outDir: "../hal-sim/ui-dist",
    emptyOutDir: true,
    sourcemap: false,
    modulePreload: false,
    cssCodeSplit: false,
    rollupOptions: {
      output: {
        entryFileNames: "assets/app.js",
        assetFileNames: "assets/app[extname]",
        inlineDynamicImports: true,
      },
    },
  },
});
